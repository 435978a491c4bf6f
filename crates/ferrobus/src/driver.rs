//! The client's driver task: runs the core master engine over a port.
//!
//! It knows no Modbus. It is the client's session around the one [`pump`](crate::pump): the
//! pump feeds the engine the bytes it reads with the time they arrived, sleeps until the
//! engine's next deadline and writes what the engine hands it; the driver takes commands
//! from the channel, hands back completions, and reopens the port after an IO error. Everything else — gaps, matching, timeouts — is the engine's.
//! On top it asks the core's [`retry`](ferrobus_proto::retry) policy what needs more than one
//! transaction: retries, per-unit backoff so that a dead device costs one timeout per backoff
//! period instead of one per poll (only silence to a checked request counts: a raw PDU or a
//! user or vendor code the device ignores never puts it in backoff), and a backoff on IO failures — after each failed open, read
//! or write the next open waits [`IO_BACKOFF_INITIAL`], doubling up to [`IO_BACKOFF_MAX`], so
//! that a dead port costs a few attempts a second instead of a busy loop, and retries span time
//! enough to ride out a short loss.
//!
//! Before each request on a serial line it drops what is waiting in the port (a stale reply
//! to a request of an earlier program, say): those bytes are handed to the engine first, so
//! that a reply owed to a timed-out request is recognised and the line's silence is timed
//! from them, and counted ([`ClientStats::flushed_bytes`], and a debug line).
//!
//! A network connection (Modbus/TCP, RTU over TCP, TLS) that stalls is made again: after a
//! timeout that left part of a reply in the buffer (a device that sent half a reply and went
//! silent on that connection, or a stream whose framing is lost), or after
//! [`STALLED_AFTER_TIMEOUTS`] timeouts in a row without any reply on it, the connection is
//! closed and a new one made before the next request (the retry, if there is one), logged and
//! counted ([`ClientStats::stalled`]). A serial port has no connection to make again: it is
//! never reopened for this.
//!
//! A request whose caller has gone (its future dropped: an interrupted command) is not sent,
//! and one already on the line is not retried; but a reply still on its way is owed. On RTU
//! and ASCII, where nothing tells a late reply from the next request's, the driver keeps the
//! port — read, not handed to anyone — until the reply in flight has come or its window has
//! passed, even once every client has gone: a program that ends then leaves no stale reply
//! for the next one. It publishes how long it may still hold the port for that
//! ([`Release`](crate::Release)), so that an application can wait for it before it exits.

mod pipelined;

use std::collections::HashMap;
use std::sync::{Arc, Mutex, PoisonError};

use ferrobus_proto::frame::Framing;
use ferrobus_proto::master::{Completion, HeardInstead, MAX_TX_LEN, Master, MasterConfig, MasterError, MasterStats};
use ferrobus_proto::pdu::{MAX_PDU_LEN, Request, Response};
use ferrobus_proto::retry::{Admit, IoBackoff, Outcome, UnitHealth, should_retry};
#[cfg(doc)]
use ferrobus_proto::retry::{IO_BACKOFF_INITIAL, IO_BACKOFF_MAX};
use ferrobus_proto::{FunctionCode, PduError};
use tokio::sync::{mpsc, oneshot, watch};

use ferrobus_proto::Instant;

use crate::clock::Clock;
use crate::config::{ClientConfig, RequestOptions};
use crate::error::Error;
use crate::port::{BoxPort, Transport};
use crate::pump::{Engine, Pump, Session, write_frame};

pub(crate) use pipelined::Pipelined;

/// One request for the driver.
pub(crate) struct Command {
    pub(crate) unit: u8,
    /// The request PDU, function code first.
    pub(crate) pdu: Vec<u8>,
    /// Send as is and return the reply unparsed.
    pub(crate) raw: bool,
    pub(crate) options: RequestOptions,
    pub(crate) reply: oneshot::Sender<Result<Reply, Error>>,
}

/// A successful outcome.
#[derive(Debug)]
pub(crate) enum Reply {
    /// The reply PDU.
    Pdu(Vec<u8>),
    /// Sent; no reply is expected (broadcast, 0x08/0x04).
    Sent,
}

/// Timeouts in a row, without any reply on the connection between them, after which a
/// network connection is taken for stalled, closed and made again before the next request.
pub const STALLED_AFTER_TIMEOUTS: u32 = 3;

/// What a client's driver has seen on its bus ([`Client::stats`](crate::Client::stats)).
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
#[non_exhaustive]
pub struct ClientStats {
    /// The master engine's counters: requests, replies, timeouts, and the late and early
    /// replies it dropped.
    pub master: MasterStats,
    /// Bytes found waiting in the port before a request and dropped (a stale reply, noise).
    pub flushed_bytes: u64,
    /// Times the port was opened (a TCP connection made), the first time included: every
    /// one past the first is a reopen or reconnect.
    pub connects: u64,
    /// Attempts to open the port (to connect) that failed.
    pub connect_failures: u64,
    /// Times an open port was lost: closed by the other end (a TCP device that dropped the
    /// connection or restarted), or a read or write that failed.
    pub disconnects: u64,
    /// Network connections closed and made again because they stalled: a timeout left part
    /// of a reply behind, or [`STALLED_AFTER_TIMEOUTS`] timed out in a row.
    pub stalled: u64,
}

/// What every driver keeps of its line besides the engine: the port and when it may be
/// reopened, the units' health and the counters its clients read.
pub(crate) struct Link {
    transport: Transport,
    config: ClientConfig,
    port: Option<BoxPort>,
    /// Whether a port was ever open: a lost one is reopened only if the transport says so.
    opened: bool,
    /// IO failures (opening, reading, writing) and when the port may be reopened.
    io: IoBackoff,
    health: HashMap<u8, UnitHealth>,
    /// Shared with the clients, updated after each request.
    stats: Arc<Mutex<ClientStats>>,
    flushed_bytes: u64,
    /// Opens, failed opens and ports lost ([`ClientStats`]).
    connects: u64,
    connect_failures: u64,
    disconnects: u64,
    stalled: u64,
    /// Timeouts in a row on the open connection, without a reply between them.
    timeouts_in_a_row: u32,
    /// Until when the port may still be held for a reply in flight or owed: watched by
    /// [`Release`](crate::Release); dropped with the driver.
    hold: watch::Sender<Option<tokio::time::Instant>>,
}

impl Link {
    pub(crate) fn new(transport: Transport, config: ClientConfig, port: Option<BoxPort>) -> Self {
        let opened = port.is_some();
        Link {
            transport,
            config,
            port,
            opened,
            io: IoBackoff::default(),
            health: HashMap::new(),
            stats: Arc::default(),
            flushed_bytes: 0,
            connects: u64::from(opened),
            connect_failures: 0,
            disconnects: 0,
            stalled: 0,
            timeouts_in_a_row: 0,
            hold: watch::Sender::new(None),
        }
    }

    /// The counters the driver keeps up to date for its clients.
    pub(crate) fn stats(&self) -> Arc<Mutex<ClientStats>> {
        Arc::clone(&self.stats)
    }

    /// How long the driver may still hold the port for a reply, as it publishes it.
    pub(crate) fn hold(&self) -> watch::Receiver<Option<tokio::time::Instant>> {
        self.hold.subscribe()
    }

    /// Publishes until when the port may be held for a reply (`None`: no reply is coming).
    fn hold_until(&self, until: Option<tokio::time::Instant>) {
        self.hold.send_if_modified(|held| {
            let changed = *held != until;
            *held = until;
            changed
        });
    }

    fn publish(&self, master: MasterStats) {
        let stats = ClientStats {
            master,
            flushed_bytes: self.flushed_bytes,
            connects: self.connects,
            connect_failures: self.connect_failures,
            disconnects: self.disconnects,
            stalled: self.stalled,
        };
        *self.stats.lock().unwrap_or_else(PoisonError::into_inner) = stats;
    }

    /// Drops the open port, counting it lost.
    fn lose_port(&mut self) {
        self.timeouts_in_a_row = 0;
        if self.port.take().is_some() {
            self.disconnects = self.disconnects.saturating_add(1);
        }
    }

    /// Notes how an attempt on the open connection ended (`mid_frame`: the engine holds part
    /// of a frame after it); closes a network connection that stalled, to be made again before
    /// the next request, and returns whether it did. Only a timeout counts: any reply, even
    /// an exception or a bad one, shows the connection alive.
    fn check_stall(&mut self, result: &Result<Reply, Error>, mid_frame: bool) -> bool {
        match result {
            Err(Error::Timeout { .. }) => self.timeouts_in_a_row = self.timeouts_in_a_row.saturating_add(1),
            Ok(_) | Err(Error::Exception { .. } | Error::BadReply { .. }) => self.timeouts_in_a_row = 0,
            _ => {}
        }
        let timed_out = matches!(result, Err(Error::Timeout { .. }));
        let stalled = timed_out && (mid_frame || self.timeouts_in_a_row >= STALLED_AFTER_TIMEOUTS);
        // A serial port has no connection to make again; a transport that does not reopen
        // would lose its only one.
        if !stalled || !self.transport.is_remote() || !self.transport.reopens() || self.port.is_none() {
            return false;
        }
        let why = if mid_frame {
            "a timeout left part of a reply behind".to_string()
        } else {
            format!("{} requests in a row timed out", self.timeouts_in_a_row)
        };
        let describe = self.transport.describe();
        tracing::warn!(
            port = %crate::log::escape(&describe),
            "the connection stalled ({why}); closing it, a new one is made for the next request"
        );
        self.port = None;
        self.timeouts_in_a_row = 0;
        self.stalled = self.stalled.saturating_add(1);
        true
    }

    /// Counts an IO failure at `now` and sets when the port may be opened next.
    fn io_failed(&mut self, now: Instant) {
        self.io.failed(now);
    }

    /// Opens the port if none is open, once the IO backoff allows; returns whether it opened
    /// one (nothing said on the old one can be heard on it).
    async fn ensure_open(&mut self, clock: &Clock) -> Result<bool, Error> {
        if self.port.is_some() {
            return Ok(false);
        }
        if self.opened && !self.transport.reopens() {
            return Err(Error::io(
                format!("reopening {}", self.transport.describe()),
                std::io::Error::new(std::io::ErrorKind::NotConnected, "the port was lost, and reopening is off"),
            ));
        }
        if let Some(at) = self.io.take_reopen_at() {
            tokio::time::sleep_until(clock.to_tokio(at)).await;
        }
        match self.transport.open(self.config.connect_timeout).await {
            Ok(port) => {
                self.port = Some(port);
                self.connects = self.connects.saturating_add(1);
                if self.opened {
                    tracing::info!(port = %self.transport.describe(), "reopened");
                }
                self.opened = true;
                Ok(true)
            }
            Err(e) => {
                self.connect_failures = self.connect_failures.saturating_add(1);
                Err(e)
            }
        }
    }

    /// The error for a port that is not open where one must be.
    fn not_connected(&self) -> Error {
        Error::io(format!("reading from {}", self.transport.describe()), std::io::ErrorKind::NotConnected.into())
    }

    /// Fails fast for a unit in backoff; returns whether this request is its probe.
    fn check_health(&mut self, unit: u8, now: Instant) -> Result<bool, Error> {
        let Some(health) = self.health.get(&unit) else { return Ok(false) };
        match health.check(now) {
            Admit::Send => Ok(false),
            Admit::Probe => Ok(true),
            Admit::Skip { until } => Err(Error::Backoff { unit, retry_in: until.saturating_duration_since(now) }),
        }
    }

    fn record_health(&mut self, command: &Command, result: &Result<Reply, Error>, now: Instant) {
        let Some(backoff) = self.config.backoff else { return };
        let unit = command.unit;
        // A broadcast gets no reply, so it says nothing of any unit's health.
        if ferrobus_proto::codes::unit::is_broadcast(unit, self.transport.framing() != crate::port::Framing::Mbap) {
            return;
        }
        let outcome = outcome(command, result);
        let health = self.health.entry(unit).or_default();
        if health.record(now, outcome, &backoff) {
            self.health.remove(&unit);
        } else if outcome == Outcome::Timeout && matches!(health.check(now), Admit::Skip { .. }) {
            tracing::info!(unit, period = ?health.period(), "unit not answering; backing off");
        }
    }

    /// Counts how an attempt ended for the IO backoff: an IO failure sets it, any other
    /// result but a port that turned out to be another device clears it.
    fn attempt_ended(&mut self, result: &Result<Reply, Error>, now: Instant) {
        match result {
            Err(Error::Io { .. }) => self.io_failed(now),
            Err(Error::NotSameDevice { .. }) => {}
            _ => self.io.succeeded(),
        }
    }
}

/// The driver of a line with one request in flight: every serial line, and Modbus/TCP unless
/// pipelining is asked for ([`pipelined`]).
pub(crate) struct Driver<F> {
    master: Master<F>,
    link: Link,
    tx: Box<[u8; MAX_TX_LEN]>,
    pump: Pump,
}

impl<F: Framing + Send + 'static> Driver<F> {
    pub(crate) fn new(master: Master<F>, transport: Transport, config: ClientConfig, port: Option<BoxPort>) -> Self {
        Driver {
            master,
            pump: Pump::new(transport.timer().sleeper()),
            link: Link::new(transport, config, port),
            tx: Box::new([0; MAX_TX_LEN]),
        }
    }

    /// The counters the driver keeps up to date for its clients.
    pub(crate) fn stats(&self) -> Arc<Mutex<ClientStats>> {
        self.link.stats()
    }

    /// How long the driver may still hold the port for a reply ([`Release`](crate::Release)).
    pub(crate) fn hold(&self) -> watch::Receiver<Option<tokio::time::Instant>> {
        self.link.hold()
    }

    /// Publishes the counters, and until when the port is held for a reply owed to a request
    /// that timed out.
    fn publish_stats(&self) {
        self.link.publish(self.master.stats());
        let owed = self.master.owed_until().filter(|&until| until > self.pump.clock().now());
        self.link.hold_until(owed.map(|until| self.pump.clock().to_tokio(until)));
    }

    /// Whether the framing's replies carry nothing that tells a late one from the next
    /// request's (RTU, ASCII; over a serial port or TCP alike).
    fn owes_late_replies(&self) -> bool {
        self.link.transport.framing() != crate::port::Framing::Mbap
    }

    pub(crate) async fn run(mut self, mut commands: mpsc::Receiver<Command>) {
        loop {
            // Between requests, keep reading: the engine must know when the line was last
            // busy, and stale bytes must not be taken for the next reply.
            let command = match self.link.port.as_mut() {
                Some(port) => match self.pump.run(port, &mut self.master, &mut Between::new(&mut commands, true)).await
                {
                    Turn::Command(command) => command,
                    // A late reply, say, or the end of a late window: counted as it comes, not
                    // at the next request.
                    Turn::Read | Turn::Woke => {
                        self.publish_stats();
                        continue;
                    }
                    Turn::Ended(None) => {
                        tracing::warn!(port = %self.link.transport.describe(), "the port closed; it will be reopened");
                        self.lose_port();
                        continue;
                    }
                    Turn::Ended(Some(e)) => {
                        tracing::warn!(port = %self.link.transport.describe(), "read failed, reopening on the next request: {e}");
                        self.lose_port();
                        continue;
                    }
                },
                None => commands.recv().await,
            };
            let Some(command) = command else { break };
            if command.reply.is_closed() {
                // Its caller has gone (an interrupted command): nobody awaits the reply.
                tracing::debug!(unit = command.unit, "a request nobody awaits any more is not sent");
                continue;
            }
            let result = self.serve(&command).await;
            self.publish_stats();
            let _ = command.reply.send(result);
        }
        self.linger().await;
    }

    /// Every client has gone: keeps reading the port while a reply is owed to a request that
    /// timed out, so that it reaches nobody (the next program on the port, say), then lets
    /// the port go.
    async fn linger(&mut self) {
        let clock = self.pump.clock();
        let Some(until) = self.master.owed_until().filter(|&until| until > clock.now()) else { return };
        let mut linger = Linger { until: clock.to_tokio(until) };
        let Some(port) = self.link.port.as_mut() else { return };
        tracing::debug!(port = %self.link.transport.describe(), "keeping the port until the reply owed has come or its window has passed");
        self.pump.run(port, &mut self.master, &mut linger).await;
        self.publish_stats();
    }

    /// The port was lost between requests: counted, and reopened after the IO backoff.
    fn lose_port(&mut self) {
        self.link.lose_port();
        self.link.io_failed(self.pump.clock().now());
        self.publish_stats();
    }

    async fn serve(&mut self, command: &Command) -> Result<Reply, Error> {
        let unit = command.unit;
        let probe = self.link.check_health(unit, self.pump.clock().now())?;
        let retries = if probe { 0 } else { command.options.retries };
        let function = FunctionCode::from_u8(command.pdu.first().copied().unwrap_or_default());
        let mut attempts = 0;
        let mut heard: Option<HeardInstead> = None;
        loop {
            attempts += 1;
            if self.owes_late_replies() {
                let clock = self.pump.clock();
                let until = clock.now().saturating_add(self.attempt_span(command));
                self.link.hold_until(Some(clock.to_tokio(until)));
            }
            let result = self.transact(command).await;
            if self.link.check_stall(&result, self.master.framing().is_mid_frame()) {
                // Nothing said on the old connection will be heard on the new one.
                self.master.abort();
            }
            if let Err(Error::Timeout { heard: Some(now), .. }) = result {
                // What tells most about the unit, over all attempts.
                if heard.is_none_or(|kept| now.weight() >= kept.weight()) {
                    heard = Some(now);
                }
            }
            self.link.attempt_ended(&result, self.pump.clock().now());
            // A caller that has gone awaits no retry.
            if should_retry(outcome(command, &result), attempts, retries) && !command.reply.is_closed() {
                tracing::debug!(unit, %function, attempts, "retrying: {:?}", result);
                continue;
            }
            self.link.record_health(command, &result, self.pump.clock().now());
            return match result {
                Err(Error::Timeout { unit, timeout, .. }) => Err(Error::Timeout { unit, timeout, attempts, heard }),
                other => other,
            };
        }
    }

    /// The longest one attempt of `command` may keep the line from now, at most: a reply
    /// owed to an earlier request, the request, its timeout, a reply still arriving then,
    /// and the late window after it.
    fn attempt_span(&self, command: &Command) -> std::time::Duration {
        let framing = self.master.framing();
        let owed = self
            .master
            .owed_until()
            .map_or(std::time::Duration::ZERO, |until| until.saturating_duration_since(self.pump.clock().now()));
        owed.saturating_add(framing.transmit_time(MAX_TX_LEN))
            .saturating_add(framing.inter_frame_gap())
            .saturating_add(command.options.timeout)
            .saturating_add(framing.transmit_time(MAX_TX_LEN))
            .saturating_add(self.late_window(command))
    }

    /// How long past a request's timeout its reply is still awaited.
    fn late_window(&self, command: &Command) -> std::time::Duration {
        self.link.config.late_window.unwrap_or(command.options.timeout.saturating_mul(2))
    }

    /// One request on the line: open the port if needed, submit, drive the engine until it
    /// completes.
    async fn transact(&mut self, command: &Command) -> Result<Reply, Error> {
        if self.link.ensure_open(self.pump.clock()).await? {
            self.master.abort();
        }
        let late_window = self.late_window(command);
        let config = &self.link.config;
        self.master.set_config(MasterConfig {
            response_timeout: command.options.timeout,
            turnaround_delay: config.turnaround_delay,
            echo_suppression: config.echo_suppression,
            late_window,
            // On a wire no reply can begin before the request has left; a pty or TCP says
            // nothing of when a reply may come.
            min_reply_delay: self.link.port.as_ref().is_some_and(|p| p.has_wire()).then_some(std::time::Duration::ZERO),
        });
        // Nothing is in flight between requests; make sure of it.
        self.master.abort();
        self.flush_input().map_err(|e| {
            self.link.lose_port();
            Error::io(format!("reading from {}", self.link.transport.describe()), e)
        })?;
        let now = self.pump.clock().now();
        let submitted = if command.raw {
            self.master.submit_raw(now, command.unit, &command.pdu)
        } else {
            let request = Request::parse(&command.pdu)?;
            self.master.submit(now, command.unit, &request)
        };
        if submitted.is_err() {
            // Only a PDU longer than 253 bytes cannot be framed.
            return Err(Error::InvalidRequest(ferrobus_proto::PduError::TooLong { len: command.pdu.len() }));
        }
        let not_connected = self.link.not_connected();
        let Some(port) = self.link.port.as_mut() else { return Err(not_connected) };
        let mut transaction = Transaction { command, tx: &mut self.tx, transport: &self.link.transport };
        let result = self.pump.run(port, &mut self.master, &mut transaction).await;
        if let Err(Error::Io { .. }) = result {
            // The port failed under the request: nothing more is heard of it.
            self.master.abort();
            self.link.lose_port();
        }
        result
    }

    /// Hands the engine what is waiting in the port, unread, and counts it as dropped.
    fn flush_input(&mut self) -> std::io::Result<()> {
        let Some(port) = self.link.port.as_mut() else { return Ok(()) };
        let n = self.pump.drain(port, &mut self.master)?;
        if n > 0 {
            self.link.flushed_bytes = self.link.flushed_bytes.saturating_add(n as u64);
            tracing::debug!(port = %self.link.transport.describe(), bytes = n, "dropped bytes waiting in the port before the request");
        }
        Ok(())
    }
}

/// One request on the line: the client's session around the pump.
struct Transaction<'a> {
    command: &'a Command,
    tx: &'a mut [u8; MAX_TX_LEN],
    transport: &'a Transport,
}

impl<F: Framing> Session<Master<F>> for Transaction<'_> {
    type Output = Result<Reply, Error>;

    /// Writes the request when the engine has it due; ends with the engine's completion.
    async fn serve(&mut self, pump: &Pump, port: &mut BoxPort, master: &mut Master<F>) -> Option<Self::Output> {
        if let Some(n) = Engine::poll_transmit(master, pump.clock().now(), &mut self.tx[..]) {
            let bytes = self.tx.get(..n).unwrap_or_default();
            if let Err(e) = write_frame(port, bytes, self.transport.rs485(), self.transport.timing()).await {
                return Some(Err(Error::io(format!("writing to {}", self.transport.describe()), e)));
            }
        }
        Engine::poll_event(master).map(|completion| convert(self.command, completion))
    }

    fn on_end(&mut self, error: Option<std::io::Error>) -> Self::Output {
        let error = error.unwrap_or_else(|| std::io::ErrorKind::UnexpectedEof.into());
        Err(Error::io(format!("reading from {}", self.transport.describe()), error))
    }
}

/// What ended a turn of the pump between a driver's own acts ([`Between`]).
pub(super) enum Turn {
    /// A command came (`None`: every client has gone).
    Command(Option<Command>),
    /// Bytes were read (a reply, a late one): the engine may have completions or new counts.
    Read,
    /// A deadline of the engine's came and was handled.
    Woke,
    /// The port reached its end (`None`) or reading failed.
    Ended(Option<std::io::Error>),
}

/// The drivers' session between their own acts (sending, retrying, reopening): the pump reads
/// the port and keeps the engine's time until a command comes (taken only while `room`), bytes
/// are read, a deadline is handled, or the port ends; the driver then acts and runs it again.
pub(super) struct Between<'c> {
    commands: &'c mut mpsc::Receiver<Command>,
    room: bool,
    turn: Option<Turn>,
}

impl<'c> Between<'c> {
    /// A turn that takes the next command from `commands` if `room`.
    pub(super) fn new(commands: &'c mut mpsc::Receiver<Command>, room: bool) -> Self {
        Between { commands, room, turn: None }
    }
}

impl<E: Engine> Session<E> for Between<'_> {
    type Output = Turn;

    async fn serve(&mut self, _pump: &Pump, _port: &mut BoxPort, _engine: &mut E) -> Option<Turn> {
        self.turn.take()
    }

    /// Cancel-safe: a read that comes first leaves the command in the channel.
    async fn wait(&mut self) {
        if self.room {
            self.turn = Some(Turn::Command(self.commands.recv().await));
        } else {
            std::future::pending::<()>().await;
        }
    }

    fn on_read(&mut self) {
        self.turn = Some(Turn::Read);
    }

    /// The pump handles the engine's deadline next; the turn ends after it.
    fn on_wake(&mut self) -> Option<Turn> {
        self.turn = Some(Turn::Woke);
        None
    }

    fn on_end(&mut self, error: Option<std::io::Error>) -> Turn {
        Turn::Ended(error)
    }
}

/// The driver's last turn, once every client has gone: reading, until `until`, while a reply
/// is owed.
struct Linger {
    until: tokio::time::Instant,
}

impl<F: Framing> Session<Master<F>> for Linger {
    type Output = ();

    /// Ends once nothing is owed any more: the reply has come and been dropped.
    async fn serve(&mut self, pump: &Pump, _port: &mut BoxPort, master: &mut Master<F>) -> Option<()> {
        while Engine::poll_event(master).is_some() {}
        (!master.owes_reply(pump.clock().now())).then_some(())
    }

    fn deadline(&mut self, _master: &Master<F>) -> Option<tokio::time::Instant> {
        Some(self.until)
    }

    /// Ends when the late window has passed without the reply.
    fn on_wake(&mut self) -> Option<()> {
        (tokio::time::Instant::now() >= self.until).then_some(())
    }

    fn on_end(&mut self, _error: Option<std::io::Error>) {}
}

/// What the retry policy sees of a result: silence counts against the unit only after a
/// request the engine checked (parsed, with a public function code); after a raw one or a
/// user or vendor code, which a device may ignore, it is [`Outcome::UncheckedTimeout`].
fn outcome(command: &Command, result: &Result<Reply, Error>) -> Outcome {
    match result {
        Ok(_) => Outcome::Reply,
        Err(Error::Exception { .. }) => Outcome::Exception,
        Err(Error::Timeout { .. }) if command.raw || !is_public(&command.pdu) => Outcome::UncheckedTimeout,
        Err(Error::Timeout { .. }) => Outcome::Timeout,
        Err(Error::BadReply { .. }) => Outcome::BadReply,
        Err(Error::Io { .. }) => Outcome::Io,
        Err(_) => Outcome::Other,
    }
}

/// Whether `pdu`'s function code is one the spec defines.
fn is_public(pdu: &[u8]) -> bool {
    pdu.first().is_some_and(|&code| FunctionCode::from_u8(code).is_public())
}

/// Turns the engine's completion into the driver's result.
fn convert(command: &Command, completion: Completion<'_>) -> Result<Reply, Error> {
    let unit = command.unit;
    let function = FunctionCode::from_u8(command.pdu.first().copied().unwrap_or_default());
    match completion {
        Completion::Response(response) => {
            // Every response the engine accepts fits a PDU; one that did not would be too long.
            let mut buf = [0u8; MAX_PDU_LEN];
            let n = response.emit(&mut buf).map_err(|e| Error::BadReply {
                unit,
                error: MasterError::BadResponse(PduError::TooLong { len: e.needed }),
            })?;
            Ok(Reply::Pdu(buf.get(..n).unwrap_or_default().to_vec()))
        }
        Completion::Raw(bytes) => Ok(Reply::Pdu(bytes.to_vec())),
        Completion::Exception(code) => Err(Error::Exception { unit, function, code }),
        Completion::Sent => Ok(Reply::Sent),
        Completion::Failed(MasterError::Timeout { heard, .. }) => {
            Err(Error::Timeout { unit, timeout: command.options.timeout, attempts: 1, heard })
        }
        Completion::Failed(error) => Err(Error::BadReply { unit, error }),
    }
}

/// Parses a reply PDU from `unit` that the driver returned; the engine has checked it already.
pub(crate) fn parse_reply(unit: u8, pdu: &[u8]) -> Result<Response<'_>, Error> {
    Response::parse(pdu).map_err(|e| Error::BadReply { unit, error: MasterError::BadResponse(e) })
}
