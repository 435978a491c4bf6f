//! The gateway: Modbus/TCP clients (or RTU over TCP) in, RTU serial lines out — or Modbus/TCP
//! (or RTU over TCP) devices out: a line may be a device on the network that takes one client
//! connection, which the gateway then shares among many (a multiplexer).
//!
//! ```text
//!   TCP connection ─┐  authorize ─ route by unit ─┐   line 0: queue ── worker ── Client ── RTU
//!   TCP connection ─┼─ (per connection)           ├─▶ (round-robin per connection, bounded)
//!   TCP connection ─┘                             └─▶ line 1: ...
//! ```
//!
//! Each line has one master, its worker: strictly one transaction at a time (on a serial line;
//! a pipelined Modbus/TCP line may keep several in flight, below) through the line's
//! [`Client`], which keeps t3.5 before every frame, waits the reply timeout and retries, waits
//! the turnaround after a broadcast, and skips a unit that stopped answering (per-unit backoff:
//! a powered-off drive costs the bus one probe now and then, never a timeout per request, and
//! the other units' requests go on meanwhile). Requests from every connection wait in one
//! bounded queue per line and are taken one per connection in turn, so no client can starve
//! another; a full queue answers 0x06 Server Device Busy at once.
//!
//! What a client is answered:
//!
//! | situation | answer |
//! |---|---|
//! | the unit's reply, or its exception | forwarded as it came |
//! | a PDU no device could take: code 0x00, 0x80–0xFF, reserved; fields missing or out of range | 0x01 or 0x03 at once, never forwarded (see below) |
//! | a unit in no routing table | 0x0A Gateway Path Unavailable |
//! | a read to unit 0 unless routed (a broadcast: no device answers it) | 0x0A |
//! | a write to unit 0 unless routed, with no serial line (nowhere to broadcast) | 0x0A |
//! | the line's queue full | 0x06 Server Device Busy, at once |
//! | silence after every retry, or the unit in backoff | 0x0B Gateway Target Device Failed to Respond |
//! | replies with a bad CRC after every retry | 0x0B, counted as CRC errors apart from silence |
//! | a reply that does not answer the request | 0x0B, counted as a bad reply |
//! | the serial port failed, or a TCP line's device cannot be reached or dropped the connection | 0x0A (the path itself is down; it is reopened, reconnected) |
//! | refused by the connection's [`Authorize`] | the exception it names ([`Rules`]: 0x01, or 0x0A for a unit) |
//! | a broadcast (unit 0 unless routed, a write: sent to the serial lines, never to a Modbus/TCP device) | nothing (the spec), or its echo with `broadcast_ack` |
//!
//! Why a bad CRC is 0x0B and not 0x04, as mbusd answers: 0x04 Server Device Failure says the
//! *device* tried and failed to perform the request, so a client takes it as the device's
//! answer (and may, for a write, believe the device refused it). A frame with a bad CRC is no
//! answer at all — it may not even come from the unit asked, and the request may or may not
//! have been executed. For the client it is the same as silence: the target did not respond
//! usably, which is what 0x0B says. The gateway's counters keep the two apart, so that the
//! person who reads them can tell a dead unit (timeouts) from a noisy line or a wrong baud
//! rate (CRC errors).
//!
//! Late replies: RTU has no transaction id. The worker sends a request only when the last has
//! ended; the client's master engine takes a reply only from the unit asked, with the
//! function code asked and, for a request it can parse, the length and echo it must have.
//! After a request timed out, the engine owes it its reply and keeps the line closed until
//! the reply has come and been dropped (counted as a late reply in the line's stats) or the
//! late window — the line's `late-window`, by default twice the reply timeout
//! ([`ClientConfig::late_window`](ferrobus::ClientConfig::late_window)), shown in its stats — has passed; after any request without a usable reply the line also stays quiet for
//! [`GatewayLine::late_guard`]. So a late reply is awaited by nobody and dropped instead of
//! being taken for the next request's, a retry's or another client's. (A reply later than the
//! timeout plus the late window, to a request of the same unit, function and length, cannot
//! be told from the next one's by any gateway: size the timeout to the device.)
//!
//! The front end checks every request before anything else, with the core's parser and
//! function-code table: a code that is no request code (0x00, the exception bit), or one the
//! spec reserves, gets 0x01 Illegal Function; a public code whose PDU is malformed gets 0x03
//! Illegal Data Value (0x02 for a range past 0xFFFF); both at once, to the sender only, and
//! counted by reason ([`Gateway::front_stats`]). User-defined codes (65–72, 100–110) are
//! forwarded as they came: a vendor's device may take them, and only it knows their layout.
//! A unit's backoff counts only silence to a request the master checked (a public code,
//! parsed), so one client's odd requests — a user code the device ignores — never make a live
//! unit answer 0x0B to every other client.
//!
//! One connection may have [`ConnectionPolicy::max_pending`] requests outstanding (queued or on the
//! line); past it the gateway stops reading that connection until a reply has gone out, so a
//! client that writes faster than the line serves is held back by TCP's flow control. That is
//! how a TCP server pushes back, and it loses nothing: a Modbus/TCP client that pipelines
//! gets every request answered, in order, where a 0x06 would fail requests it could simply
//! have waited for (the lines' queues, shared by every connection, still answer 0x06 when
//! full).
//!
//! A line to a Modbus/TCP device ([`Transport::tcp`]) is served as a serial line is: one
//! request at a time on its one connection, in turns per client connection, with the cache,
//! the rules and the per-unit backoff; the reply is matched by the MBAP transaction id the
//! line's master gave the request (a reply under another id is dropped). With
//! [`ClientConfig::in_flight`](ferrobus::ClientConfig::in_flight) past 1 its worker keeps that
//! many requests outstanding on the connection, taken in the same turns, each matched by its
//! own id: a device that answers its connection's requests in order then serves them back to
//! back, without a round trip between two. The gateway does not
//! connect it at start: a device that is down keeps nobody else from being served. Its
//! connection is made on the first request and made again after the device closes it or a
//! read fails, after a backoff that grows with each failure (the driver's, as for a serial
//! port's reopening); meanwhile its requests get 0x0A at once, without waiting for an attempt
//! of their own (a device that does not answer a connect would cost each one the connect
//! timeout), and the first request after the backoff tries again. A serial line whose port
//! failed is held the same way. The line's counters show its connects, failed connects and
//! lost connections.
//!
//! The reverse direction, a slave on the serial line forwarding to Modbus/TCP servers, is
//! [`serve_reverse`].
//!
//! The front end's per-connection code ([`Gateway::serve_connection`]) is generic over the
//! stream, and every request passes the connection's [`Authorize`] first: a TLS acceptor with
//! a roles policy serves its connections through the same function.

mod authorize;
mod back;
mod cache;
pub mod config;
mod front;
pub mod reload;
mod reverse;
mod screen;
pub mod stats;
#[cfg(feature = "status")]
pub mod status;
#[cfg(feature = "tls")]
mod tls;

use std::io;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, RwLock};
use std::time::Duration;

use ferrobus_proto::ExceptionCode;
use ferrobus_proto::frame::AduHeader;
use ferrobus_proto::master::pipeline::MAX_IN_FLIGHT;
use tokio::io::{AsyncRead, AsyncWrite};
use tokio::net::TcpListener;
use tokio::sync::oneshot;

pub use authorize::{AllowAll, Authorize, Chain, Rules};
use back::{Job, LineQueue, Worker};
use cache::Cache;
use reload::{Fate, Plan};
pub use reverse::{OnFailure, Upstream, serve_reverse};
use stats::{FrontStats, LineTraffic};

use ferrobus::server::{ConnectionPolicy, TcpLimits};
use ferrobus::{Client, ClientConfig, Error, Transport};

/// Where requests for one unit go.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Route {
    /// The line's index in [`GatewayConfig::lines`].
    pub line: usize,
    /// The unit's address on that line (the same as the client's, unless renumbered).
    pub unit: u8,
}

/// The routing table: for each unit a client may address, the line and the unit on it.
#[derive(Clone, PartialEq, Eq)]
pub struct Routes {
    table: Box<[Option<Route>; 256]>,
}

/// The routes only, by unit.
impl std::fmt::Debug for Routes {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_map().entries(self.iter()).finish()
    }
}

impl Default for Routes {
    fn default() -> Self {
        Routes { table: Box::new([None; 256]) }
    }
}

impl Routes {
    /// An empty table: every unit gets 0x0A.
    pub fn new() -> Self {
        Self::default()
    }

    /// Every unit id, 0 to 255, on `line`, each under its own address: for a Modbus/TCP
    /// device, to which every unit id is its own to interpret (0xFF, the spec's for a device
    /// addressed by its IP address, and 0 among them: Modbus/TCP has no broadcast).
    pub fn every_id_on(line: usize) -> Self {
        let mut routes = Self::new();
        for unit in 0..=u8::MAX {
            routes.set(unit, Route { line, unit });
        }
        routes
    }

    /// Units 1 to 247 on `line`, each under its own address.
    pub fn all_on(line: usize) -> Self {
        let mut routes = Self::new();
        for unit in 1..=247 {
            routes.set(unit, Route { line, unit });
        }
        routes
    }

    /// Routes `unit` (as clients address it) to `route`, replacing any route it had.
    pub fn set(&mut self, unit: u8, route: Route) {
        if let Some(slot) = self.table.get_mut(usize::from(unit)) {
            *slot = Some(route);
        }
    }

    /// Where `unit` goes, if anywhere.
    pub fn get(&self, unit: u8) -> Option<Route> {
        self.table.get(usize::from(unit)).copied().flatten()
    }

    /// Every route, by the client's unit.
    pub fn iter(&self) -> impl Iterator<Item = (u8, Route)> + '_ {
        (0..=u8::MAX).filter_map(|unit| self.get(unit).map(|r| (unit, r)))
    }
}

/// One line behind the gateway: a serial port, or a device over TCP.
#[derive(Clone, Debug)]
pub struct GatewayLine {
    /// The port and its framing (RTU, or ASCII) and timing, or the TCP device (Modbus/TCP,
    /// RTU over TCP).
    pub transport: Transport,
    /// Reply timeout, retries, turnaround, backoff of its master.
    pub client: ClientConfig,
    /// Requests that may wait for the line; past it, 0x06 at once.
    pub queue: usize,
    /// After a request that got no usable reply, how long the line stays quiet before the
    /// next request, so that a late reply is dropped and not taken for the next one's. Not
    /// kept on a Modbus/TCP line ([`Framing::Mbap`](ferrobus::Framing::Mbap)): its transaction
    /// ids tell a late reply from the next one's, and the line is not held for it.
    pub late_guard: Duration,
}

impl GatewayLine {
    /// A line on `transport` with `client`'s settings, a queue of 64 and a late-reply guard
    /// of 100 ms.
    pub fn new(transport: Transport, client: ClientConfig) -> Self {
        GatewayLine { transport, client, queue: DEFAULT_QUEUE, late_guard: DEFAULT_LATE_GUARD }
    }
}

/// A line's queue unless set: [`GatewayLine::queue`].
const DEFAULT_QUEUE: usize = 64;

/// A line's late-reply guard unless set: [`GatewayLine::late_guard`].
const DEFAULT_LATE_GUARD: Duration = Duration::from_millis(100);

/// What the gateway receives on its connections.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub enum Inbound {
    /// Modbus/TCP (MBAP), the receiver strict: a bad header closes the connection.
    #[default]
    Mbap,
    /// RTU frames over TCP (CRC and all).
    RtuOverTcp,
}

impl Inbound {
    fn transport(self) -> Transport {
        match self {
            Inbound::Mbap => Transport::tcp("gateway client"),
            Inbound::RtuOverTcp => Transport::rtu_over_tcp("gateway client"),
        }
    }
}

/// How the gateway's front end listens.
#[derive(Clone, Debug, Default)]
pub struct FrontConfig {
    /// What clients send.
    pub inbound: Inbound,
    /// The listener's connection caps, and each connection's policy
    /// ([`TcpLimits::connection`]: idle and frame timeouts, requests outstanding; past
    /// [`ConnectionPolicy::max_pending`] its socket is not read until a reply has gone out).
    pub limits: TcpLimits,
}

/// A gateway's settings.
#[derive(Clone, Debug)]
pub struct GatewayConfig {
    /// The lines: serial ports, TCP devices.
    pub lines: Vec<GatewayLine>,
    /// Which unit goes where.
    pub routes: Routes,
    /// Answer a broadcast with its echo once it has gone out (for clients that wait for a
    /// reply to everything); by default a broadcast gets no reply, as the spec says.
    pub broadcast_ack: bool,
    /// Answer reads from a cache of replies younger than this (`None`: no cache).
    pub cache_max_age: Option<Duration>,
}

/// Why a gateway did not start.
#[derive(Clone, Debug, thiserror::Error)]
#[non_exhaustive]
pub enum GatewayError {
    /// A unit is routed to a line the gateway does not have: a mistake in the settings.
    #[error("unit {unit} is routed to line {line}, but there are {lines} lines (numbered from 0)")]
    Routing {
        /// The unit, as clients address it.
        unit: u8,
        /// The line it is routed to.
        line: usize,
        /// How many lines there are.
        lines: usize,
    },
    /// A serial line's port could not be opened.
    #[error("{source}")]
    Io {
        /// The line, numbered from 0.
        line: usize,
        /// What went wrong, with the port named.
        #[source]
        source: Error,
    },
}

/// Refuses a route to a line that `config` does not have.
fn check_routes(config: &GatewayConfig) -> Result<(), GatewayError> {
    match config.routes.iter().find(|(_, r)| r.line >= config.lines.len()) {
        Some((unit, route)) => Err(GatewayError::Routing { unit, line: route.line, lines: config.lines.len() }),
        None => Ok(()),
    }
}

/// A running gateway: the lines' workers. Clone it to serve connections from several tasks.
#[derive(Clone)]
pub struct Gateway {
    inner: Arc<Inner>,
}

pub(crate) struct Inner {
    /// The lines and the routes, swapped whole by a reload: a request is routed and queued
    /// on one table.
    table: RwLock<Arc<Table>>,
    broadcast_ack: bool,
    cache: Option<Arc<Cache>>,
    connections: AtomicU64,
    front: Mutex<FrontStats>,
}

impl Gateway {
    /// Checks the routes, opens every serial line (a port that cannot be opened fails here,
    /// named) and starts its worker on the current tokio runtime. A line to a device on the
    /// network ([`Transport::is_remote`]) is not connected here: a device that is down must
    /// not keep the gateway from serving the others. It connects on its first request and
    /// again after a loss (after a backoff that grows with each failure), and its requests
    /// get 0x0A meanwhile.
    pub async fn start(config: GatewayConfig) -> Result<Gateway, GatewayError> {
        check_routes(&config)?;
        let cache = config.cache_max_age.map(|age| Arc::new(Cache::new(age)));
        let mut lines = Vec::with_capacity(config.lines.len());
        for (index, line) in config.lines.iter().enumerate() {
            let client = open(index, line).await?;
            lines.push(Some(Line::start(line, client, cache.as_ref())));
        }
        let inner = Inner {
            table: RwLock::new(Arc::new(Table { lines, routes: config.routes })),
            broadcast_ack: config.broadcast_ack,
            cache,
            connections: AtomicU64::new(0),
            front: Mutex::default(),
        };
        Ok(Gateway { inner: Arc::new(inner) })
    }

    /// Carries out `plan`, from the running lines to `config`'s ([`reload::plan`] of the two
    /// files): an unchanged line runs on, untouched, at its new place; the routes are swapped
    /// for new requests; connections stay open. First the added lines' serial ports are
    /// opened: one that cannot be opened refuses the reload ([`GatewayError::Io`]), nothing
    /// stopped. Then the changed and removed lines stop taking requests (those queued and on
    /// the line are served, a reply owed is awaited), and once a changed line's driver has
    /// let its port go, the line opens anew; meanwhile its requests get 0x0A. A changed
    /// line's port that does not open again is held as a lost port is (0x0A, opened on a
    /// later request), and logged. Returns the releases of the lines started, to wait on
    /// before the program exits ([`Gateway::releases`]).
    pub async fn reload(&self, plan: &Plan, config: GatewayConfig) -> Result<Vec<ferrobus::Release>, GatewayError> {
        check_routes(&config)?;
        let fate = |index: usize| plan.lines.get(index).copied().unwrap_or(Fate::Added);
        let mut added = Vec::new();
        for (index, line) in config.lines.iter().enumerate() {
            if fate(index) == Fate::Added {
                added.push((index, open(index, line).await?));
            }
        }
        let cache = self.inner.cache.as_ref();
        let running = self.inner.table();
        let mut lines: Vec<Option<Line>> = (0..config.lines.len())
            .map(|index| match fate(index) {
                Fate::Unchanged { was } => running.line(was).cloned(),
                Fate::Changed { .. } | Fate::Added => None,
            })
            .collect();
        let mut started = Vec::new();
        for (index, client) in added {
            if let (Some(slot), Some(line)) = (lines.get_mut(index), config.lines.get(index)) {
                started.push(client.release());
                *slot = Some(Line::start(line, client, cache));
            }
        }
        let changed: Vec<(usize, usize)> = (0..config.lines.len())
            .filter_map(|index| match fate(index) {
                Fate::Changed { was } => Some((index, was)),
                Fate::Unchanged { .. } | Fate::Added => None,
            })
            .collect();
        let stopping = changed.iter().map(|(_, was)| *was).chain(plan.removed.iter().copied());
        let mut ending = Vec::new();
        for was in stopping {
            if let Some(line) = running.line(was) {
                line.queue.close();
                ending.push((was, line.client.release()));
            }
        }
        drop(running);
        self.inner.swap(Table { lines, routes: config.routes });
        for (index, was) in changed {
            if let Some((_, release)) = ending.iter().find(|(w, _)| *w == was) {
                release.clone().ended().await;
            }
            let Some(line) = config.lines.get(index) else { continue };
            let client = match open(index, line).await {
                Ok(client) => client,
                Err(e) => {
                    tracing::error!(
                        line = index,
                        "reload: {e}; the line is held as a lost port, opened on a later request"
                    );
                    Client::spawn(line.transport.clone(), line.client)
                }
            };
            started.push(client.release());
            self.inner.set(index, Line::start(line, client, cache));
        }
        Ok(started)
    }

    /// When each line's driver lets its port go, once the gateway is dropped: a program waits
    /// on them before it exits, so that a reply still on its way to a line reaches nobody else
    /// ([`Client::release`]).
    pub fn releases(&self) -> Vec<ferrobus::Release> {
        self.inner.table().lines.iter().flatten().map(|line| line.client.release()).collect()
    }

    /// What each line has counted so far (a line that a reload is opening anew: nothing yet).
    pub fn stats(&self) -> Vec<LineTraffic> {
        let table = self.inner.table();
        table
            .lines
            .iter()
            .map(|line| match line {
                Some(line) => {
                    let mut stats = line.queue.stats().clone();
                    stats.dropped(&line.client.stats());
                    stats
                }
                None => LineTraffic { name: "(reopening)".into(), ..LineTraffic::default() },
            })
            .collect()
    }

    /// What the front end has refused so far, before any line, by reason.
    pub fn front_stats(&self) -> FrontStats {
        self.inner.front().clone()
    }

    /// Serves one client connection on `stream` until the client closes it (`Ok`), it fails,
    /// or it is closed for cause on `connection`'s policy (an error carrying a
    /// [`Closed`](ferrobus::server::Closed) reason, [`close_reason`](ferrobus::server::close_reason)).
    /// `peer` names the client in the logs; every request passes `authorize` first.
    pub async fn serve_connection<S>(
        &self,
        stream: S,
        peer: &str,
        inbound: Inbound,
        authorize: &mut dyn Authorize,
        connection: ConnectionPolicy,
    ) -> io::Result<()>
    where
        S: AsyncRead + AsyncWrite + Unpin + Send + 'static,
    {
        front::serve(&self.inner, stream, peer, inbound, authorize, connection).await
    }

    /// Serves every connection `listener` accepts, as `front` says, within its limits (the
    /// hardened TCP server's accept loop: connection cap, descriptor backoff, counted closes),
    /// each with the [`Authorize`] that `authorize` makes for its peer. Runs until dropped.
    pub async fn serve_tcp<A>(&self, listener: TcpListener, front: FrontConfig, authorize: A) -> io::Result<()>
    where
        A: Fn(SocketAddr) -> Box<dyn Authorize> + Send + Sync + 'static,
    {
        let FrontConfig { inbound, limits } = front;
        let connection = limits.connection;
        let authorize = Arc::new(authorize);
        ferrobus::server::accept_connections(listener, &limits, |stream, peer| {
            let gateway = self.clone();
            let authorize = Arc::clone(&authorize);
            async move {
                let mut auth = authorize(peer);
                gateway.serve_connection(stream, &peer.to_string(), inbound, auth.as_mut(), connection).await
            }
        })
        .await
    }
}

impl Drop for Inner {
    /// The lines' workers end once the requests queued are done.
    fn drop(&mut self) {
        for line in self.table().lines.iter().flatten() {
            line.queue.close();
        }
    }
}

/// Opens line `index` (a serial port; a device on the network connects on its first request).
async fn open(index: usize, line: &GatewayLine) -> Result<Client, GatewayError> {
    if line.transport.is_remote() {
        // A device on the network may be down, or not up yet: the line connects on its first
        // request and again after each loss, and fails its requests meanwhile, as a serial
        // line does while its port is being reopened.
        return Ok(Client::spawn(line.transport.clone(), line.client));
    }
    Client::connect(line.transport.clone(), line.client)
        .await
        .map_err(|source| GatewayError::Io { line: index, source })
}

/// The lines and routes that requests are sent by.
struct Table {
    /// By index; `None` while a reload opens the line anew.
    lines: Vec<Option<Line>>,
    routes: Routes,
}

/// One running line: its queue (with its counters) and its client.
#[derive(Clone)]
struct Line {
    queue: Arc<LineQueue>,
    /// For what its driver counts between requests (connections).
    client: Client,
}

impl Line {
    /// Starts `line`'s worker over `client`.
    fn start(line: &GatewayLine, client: Client, cache: Option<&Arc<Cache>>) -> Line {
        let name = line.transport.describe();
        let late_window = (line.transport.framing() != ferrobus::Framing::Mbap)
            .then(|| line.client.late_window.unwrap_or(line.client.timeout.saturating_mul(2)));
        let stats = Arc::new(Mutex::new(LineTraffic { name, late_window, ..LineTraffic::default() }));
        let queue = Arc::new(LineQueue::new(line.queue, stats));
        // A Modbus/TCP device's late reply carries its own transaction id: the master drops
        // it, so the line need not stay quiet for it, and may keep several requests in
        // flight.
        let worker = if line.transport.framing() == ferrobus::Framing::Mbap {
            Worker { in_flight: line.client.in_flight.clamp(1, MAX_IN_FLIGHT), late_guard: Duration::ZERO }
        } else {
            Worker { in_flight: 1, late_guard: line.late_guard }
        };
        tokio::spawn(back::run(Arc::clone(&queue), client.clone(), cache.cloned(), worker));
        Line { queue, client }
    }
}

impl Table {
    fn line(&self, index: usize) -> Option<&Line> {
        self.lines.get(index).and_then(Option::as_ref)
    }

    /// Queues `job` on line `line` for `connection`; the exception to answer when it cannot:
    /// 0x06 when the queue is full, 0x0A while a reload opens the line anew.
    fn submit(&self, line: usize, connection: u64, job: Job) -> Result<(), ExceptionCode> {
        let queue = &self.line(line).ok_or(ExceptionCode::GatewayPathUnavailable)?.queue;
        queue.submit(connection, job).map_err(|_| ExceptionCode::ServerDeviceBusy)
    }

    /// The running lines with their index.
    fn running(&self) -> impl Iterator<Item = (usize, &Line)> {
        self.lines.iter().enumerate().filter_map(|(i, line)| line.as_ref().map(|l| (i, l)))
    }
}

impl Inner {
    /// The table now.
    fn table(&self) -> Arc<Table> {
        Arc::clone(&self.table.read().unwrap_or_else(std::sync::PoisonError::into_inner))
    }

    /// Puts `table` in place.
    fn swap(&self, table: Table) {
        *self.table.write().unwrap_or_else(std::sync::PoisonError::into_inner) = Arc::new(table);
    }

    /// Puts line `index` in place, opened anew.
    fn set(&self, index: usize, line: Line) {
        let mut table = self.table.write().unwrap_or_else(std::sync::PoisonError::into_inner);
        let mut lines = table.lines.clone();
        if let Some(slot) = lines.get_mut(index) {
            *slot = Some(line);
        }
        *table = Arc::new(Table { lines, routes: table.routes.clone() });
    }

    fn next_connection(&self) -> u64 {
        self.connections.fetch_add(1, Ordering::Relaxed)
    }

    fn front(&self) -> std::sync::MutexGuard<'_, FrontStats> {
        self.front.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    fn cached(&self, table: &Table, unit: u8, pdu: &[u8]) -> Option<Vec<u8>> {
        let reply = self.cache.as_ref()?.get(unit, pdu)?;
        if let Some(line) = table.routes.get(unit).and_then(|r| table.line(r.line)) {
            let mut stats = line.queue.stats();
            let counters = stats.units.entry(unit).or_default();
            counters.cached = counters.cached.saturating_add(1);
            stats.total.cached = stats.total.cached.saturating_add(1);
        }
        Some(reply)
    }

    /// Whether any line has a broadcast: a serial line, or RTU over TCP to one.
    fn broadcasts(&self) -> bool {
        self.table().running().any(|(_, line)| line.client.has_broadcast())
    }

    /// Sends a broadcast on every line that has one (not to a Modbus/TCP device, which would
    /// take unit 0 as addressed to itself); with `broadcast_ack`, what completes when every
    /// such line has sent it (its reply `None`: the echo), or 0x06 if no line could take it.
    fn broadcast(&self, connection: u64, header: AduHeader, pdu: &[u8]) -> Option<oneshot::Receiver<Option<Vec<u8>>>> {
        let mut done = Vec::new();
        let table = self.table();
        for (line, running) in table.running().filter(|(_, l)| l.client.has_broadcast()) {
            let (reply, rx) = oneshot::channel();
            let job = Job { unit_in: header.unit, unit_out: 0, pdu: pdu.to_vec(), reply, broadcast: true };
            if running.queue.submit(connection, job).is_ok() {
                done.push(rx);
            } else {
                tracing::info!(line, "broadcast not queued: the line's queue is full");
            }
        }
        if !self.broadcast_ack {
            return None;
        }
        let (ack, rx) = oneshot::channel();
        let function = pdu.first().copied().unwrap_or_default();
        tokio::spawn(async move {
            let busy = done.is_empty();
            for line in done {
                // An exception on one line is the answer; a line that stopped counts as sent.
                if let Ok(Some(reply)) = line.await {
                    let _ = ack.send(Some(reply));
                    return;
                }
            }
            let busy = busy.then(|| back::exception(function, ferrobus_proto::ExceptionCode::ServerDeviceBusy.value()));
            let _ = ack.send(busy);
        });
        Some(rx)
    }
}

/// The counters of every line, one block each, then the front end's refusals: what SIGUSR1
/// and the exit print.
pub fn report(stats: &[LineTraffic], front: &FrontStats) -> String {
    let mut report: String = stats.iter().map(ToString::to_string).collect();
    report.push_str(&front.to_string());
    report
}
