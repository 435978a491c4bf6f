//! The server driver: runs the core slave engine over a port, or over every connection a TCP
//! listener accepts.
//!
//! Like the client's driver it knows no Modbus, and runs on the same one driver loop (see the
//! crate's opening doc): it feeds bytes with their arrival time, sleeps until the engine's
//! next deadline ([`Timer::Precise`] on serial lines, so that a reply due at t3.5 + wait is
//! not a millisecond late), writes the reply the engine hands it, and reports what happened.
//! The engine runs deferred: it frames and admits each request and keeps its slot, its order
//! and its reply timing; the session hands each one to the [`Service`] — one call per request,
//! a [`Shared`] handler locked once for it — after the [`ServerOptions::authorize`] filter
//! (a TLS client's role). A [`ReplyFilter`] may drop, delay or alter replies on their way out:
//! the simulator's fault injection.
//!
//! Over TCP ([`serve_tcp_with`]) a connection's trouble never ends the server: running out of
//! file descriptors pauses accepting for [`ACCEPT_BACKOFF`] while the open connections are
//! served; other accept and socket-option errors are logged and counted ([`TcpStats`]).
//! Past its source's share ([`TcpLimits::max_per_source`] connections; a TLS server also
//! bounds its source's handshakes in progress), a new connection is accepted and closed at
//! once, so that one host cannot take every slot; past [`TcpLimits::max_connections`] the
//! connection least worth keeping (one in its handshake, one never answered, the one idle
//! longest) is closed to make room, so that many hosts cannot lock a new client out
//! ([`TcpLimits`] says which). A connection is closed on its [`ConnectionPolicy`], which the
//! core's slave engine applies on its own time: when it is idle (nothing outstanding), when a
//! frame begun is not finished in time, or when its MBAP framing is lost (a bad header:
//! nothing after it is executed); each is logged and counted. Requests
//! written back to back are answered in order; while the engine's reply queue is full the
//! driver stops reading the socket, so a client that does not read its replies is slowed by
//! TCP, not answered out of order or dropped.

mod accept;
mod authorize;
mod trim;

use std::collections::VecDeque;
use std::future::Future;
use std::io;
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::time::Duration;

use ferrobus_proto::FunctionCode;
use ferrobus_proto::frame::{Framing, LineTiming};
use ferrobus_proto::master::MAX_TX_LEN;
use ferrobus_proto::pdu::AddressRange;
use ferrobus_proto::slave::{Disposition, Handler, RequestId, Slave, SlaveConfig, SlaveEvent};
use tokio::net::TcpListener;

use crate::port::{BoxPort, Rs485, Transport};
use crate::pump::{Codec, Pump, Role, Session, write_frame};
use crate::timer::Timer;

pub use accept::{ACCEPT_BACKOFF, TcpCounts, TcpLimits, TcpStats};
pub use accept::{Handshake, Tracked, Tracker, accept_connections, accept_handshaking};
pub use authorize::Authorize;
pub use ferrobus_proto::slave::{Closed, ConnectionPolicy};

/// What happens to a reply on its way out.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Fate {
    /// Send it now.
    Send,
    /// Send it this much later.
    Delay(Duration),
    /// Send it now, one byte at a time with `gap` between bytes (a slow or stuttering
    /// device; on a serial line a gap past t1.5 breaks the frame).
    Trickle {
        /// The pause after each byte but the last.
        gap: Duration,
    },
    /// Never send it.
    Drop,
}

/// What a reply answers: the request as the engine reported it.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Answering {
    /// The unit the request was for.
    pub unit: u8,
    /// Its function code.
    pub function: FunctionCode,
    /// The addresses it touches.
    pub addresses: [Option<AddressRange>; 2],
}

impl Answering {
    /// What a reply to the request of `event` answers, if `event` is a request that gets one.
    pub fn of(event: &SlaveEvent) -> Option<Answering> {
        match *event {
            SlaveEvent::Request {
                unit,
                function,
                addresses,
                disposition: Disposition::Replied(_) | Disposition::Refused(..),
                ..
            } => Some(Answering { unit, function, addresses }),
            _ => None,
        }
    }
}

/// Decides the fate of each reply, and may change its bytes.
pub trait ReplyFilter: Send {
    /// `frame` is the reply as framed for the wire; the filter may change it, its length
    /// included. `answering` is the request it answers, when the engine reported one (the
    /// replies of one connection are matched to its requests in order).
    fn filter(&mut self, answering: Option<&Answering>, frame: &mut Vec<u8>) -> Fate;
}

/// What a server saw and did, for logs and monitors.
#[derive(Clone, PartialEq, Eq, Debug)]
pub enum ServerEvent {
    /// The engine's report of a request or a frame on the bus.
    Slave {
        /// The report.
        event: SlaveEvent,
        /// When it was made.
        at: tokio::time::Instant,
    },
    /// A reply went out.
    Sent {
        /// The frame.
        frame: Vec<u8>,
        /// When the engine had it due.
        due: tokio::time::Instant,
        /// When its write began: the reply's start as far as the server decides it. The
        /// write itself (the kernel's, and with RTS direction control the frame's whole
        /// transmission) comes after.
        at: tokio::time::Instant,
    },
    /// A reply was dropped by the filter.
    Dropped {
        /// The frame.
        frame: Vec<u8>,
    },
}

/// A handler shared by several engines (one per TCP connection) or with the program (a
/// simulator's model that also runs on its own).
pub struct Shared<H>(pub Arc<Mutex<H>>);

impl<H> Clone for Shared<H> {
    fn clone(&self) -> Self {
        Shared(Arc::clone(&self.0))
    }
}

impl<H> Shared<H> {
    /// Shares `handler`.
    pub fn new(handler: H) -> Self {
        Shared(Arc::new(Mutex::new(handler)))
    }

    /// Locks it (a handler that panicked is still used: its data is plain values).
    pub fn lock(&self) -> MutexGuard<'_, H> {
        self.0.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

/// What answers the requests a server's engine hands out: one call per request, which
/// finishes it ([`Slave::answer_with`] through a [`Handler`], or [`Slave::respond`],
/// [`Slave::refuse`], [`Slave::ignore`]). A request left unfinished gets no reply once the
/// engine's answer limit passes.
///
/// Every [`Handler`] is one, and so is a [`Shared`] handler, locked once per request.
pub trait Service: Send {
    /// Finishes request `id`, just handed out by `slave`.
    fn answer<F: Framing>(&mut self, slave: &mut Slave<F>, id: RequestId);
}

impl<H: Handler + Send + ?Sized> Service for H {
    fn answer<F: Framing>(&mut self, slave: &mut Slave<F>, id: RequestId) {
        // The id was just handed out: it is known.
        let _ = slave.answer_with(id, self);
    }
}

impl<H: Handler + Send> Service for Shared<H> {
    fn answer<F: Framing>(&mut self, slave: &mut Slave<F>, id: RequestId) {
        // One lock for the whole request: admission, the data call, the response wait.
        let _ = slave.answer_with(id, &mut *self.lock());
    }
}

/// How a server runs, besides its engine.
pub struct ServerOptions {
    /// How deadlines are waited for.
    pub timer: Timer,
    /// RS-485 direction control (RTS is raised around each reply when [`Rs485::Rts`]).
    pub rs485: Rs485,
    /// The line timing (for how long RTS stays up).
    pub timing: LineTiming,
    /// Fault injection on replies.
    pub filter: Option<Box<dyn ReplyFilter>>,
    /// Called with every event.
    pub observer: Option<Box<dyn FnMut(ServerEvent) + Send>>,
    /// When the connection is closed, and how many requests it may have outstanding (`None`:
    /// the listener's [`TcpLimits::connection`] over TCP, [`ConnectionPolicy::NONE`] on a
    /// serial line).
    pub connection: Option<ConnectionPolicy>,
    /// Checks every request before it is answered (a TLS client's role): `Err(code)`
    /// answers it with exception `code` (a broadcast: not at all) and the [`Service`] never
    /// sees it.
    pub authorize: Option<Box<dyn Authorize>>,
}

/// The error a session ends with when it closes its connection for `reason` (what
/// [`close_reason`] finds again).
pub fn close_error(reason: Closed) -> io::Error {
    let kind = if reason == Closed::BadHeader { io::ErrorKind::InvalidData } else { io::ErrorKind::TimedOut };
    io::Error::new(kind, reason)
}

/// Why the server closed the connection itself, if `error` says it did ([`close_error`]).
pub fn close_reason(error: &io::Error) -> Option<Closed> {
    error.get_ref().and_then(|e| e.downcast_ref::<Closed>()).copied()
}

impl ServerOptions {
    /// Options for a line with `timing`, waiting with `timer`: no direction control, no
    /// filter, no observer.
    pub fn new(timing: LineTiming, timer: Timer) -> Self {
        ServerOptions {
            timer,
            rs485: Rs485::Auto,
            timing,
            filter: None,
            observer: None,
            connection: None,
            authorize: None,
        }
    }

    /// Options fitting `transport`: its timer, RS-485 mode and timing.
    pub fn for_transport(transport: &Transport) -> Self {
        ServerOptions {
            timer: transport.timer(),
            rs485: transport.rs485(),
            timing: *transport.timing(),
            filter: None,
            observer: None,
            connection: None,
            authorize: None,
        }
    }

    fn observe(&mut self, event: ServerEvent) {
        if let Some(observer) = self.observer.as_mut() {
            observer(event);
        }
    }
}

/// The most requests remembered for replies not yet sent (a peer that pipelines more, with
/// replies the engine never sends, cannot grow the queue).
const ANSWERING_MAX: usize = 64;

/// Runs `slave` over `port`, answering every request through `service` (a [`Handler`], a
/// [`Shared`] one), until the port fails or closes.
/// Returns the engine (with its counters) and the error that ended it, if any.
///
/// The engine (some KiB with its request slots) and the session's buffers live on the heap, once:
/// the future holds pointers to them. (Taken by value into an `async fn`, the engine was
/// stored in the future twice, as the argument and as the engine, and a TCP server's task per
/// connection with it.)
pub fn serve<'a, F: Framing + 'a, S: Service + ?Sized>(
    slave: Slave<F>,
    mut port: BoxPort,
    service: &'a mut S,
    options: &'a mut ServerOptions,
) -> impl Future<Output = (Slave<F>, io::Result<()>)> + 'a {
    let mut engine = Box::new(slave);
    async move {
        let mut pump = Pump::new(options.timer.sleeper());
        engine.set_connection_policy(options.connection.unwrap_or_default(), pump.clock().now());
        let mut session = Box::new(Replies {
            service,
            options,
            tx: [0u8; MAX_TX_LEN],
            delayed: VecDeque::new(),
            answering: VecDeque::new(),
            woke: false,
        });
        let ended = pump.run(&mut port, &mut *engine, &mut *session).await;
        (*engine, ended)
    }
}

/// The server's session around the pump: answers the requests the engine hands out (the
/// authorization filter first, then the service), reports events, passes replies through
/// the reply filter and writes them in order, and closes the port when the engine is done with
/// the connection ([`Slave::closed`]).
struct Replies<'o, S: ?Sized> {
    service: &'o mut S,
    options: &'o mut ServerOptions,
    tx: [u8; MAX_TX_LEN],
    /// Replies held back by the filter, in order, with when to send them. Over TCP several
    /// replies may be pending; one sent now waits behind those held, to keep the order.
    delayed: VecDeque<(Outgoing, tokio::time::Instant)>,
    /// The requests whose replies have not gone out yet, oldest first.
    answering: VecDeque<Answering>,
    /// A deadline came: held replies now due go out before anything else.
    woke: bool,
}

impl<F: Framing, S: Service + ?Sized> Session<Slave<F>> for Replies<'_, S> {
    type Output = io::Result<()>;

    async fn serve(&mut self, pump: &Pump, port: &mut BoxPort, engine: &mut Slave<F>) -> Option<Self::Output> {
        if let Some(closed @ (Closed::Idle(_) | Closed::UnfinishedFrame(_))) = engine.closed() {
            // (The replies owed before a bad header still go out.)
            return Some(Err(close_error(closed)));
        }
        answer_requests(engine, &mut *self.service, &mut self.options.authorize);
        let idle = engine.connection_policy().idle;
        if std::mem::take(&mut self.woke) {
            while self.delayed.front().is_some_and(|(_, at)| *at <= tokio::time::Instant::now()) {
                let Some((reply, _)) = self.delayed.pop_front() else { break };
                if let Err(e) = send(port, reply, idle, self.options).await {
                    return Some(Err(e));
                }
            }
        }
        let now = pump.clock().now();
        // Events first: a request is known before its reply leaves (on TCP, at once).
        take_events(engine, &mut self.answering, self.options);
        loop {
            let due = engine.reply_due().map_or_else(tokio::time::Instant::now, |t| pump.clock().to_tokio(t));
            let Some(n) = engine.poll_transmit(now, &mut self.tx) else { break };
            let mut frame = self.tx.get(..n).unwrap_or_default().to_vec();
            let request = self.answering.pop_front();
            let fate = self.options.filter.as_mut().map_or(Fate::Send, |f| f.filter(request.as_ref(), &mut frame));
            let (wait, gap) = match fate {
                Fate::Send => (Duration::ZERO, None),
                Fate::Delay(d) => (d, None),
                Fate::Trickle { gap } => (Duration::ZERO, Some(gap)),
                Fate::Drop => {
                    self.options.observe(ServerEvent::Dropped { frame });
                    continue;
                }
            };
            let reply = Outgoing { frame, due, gap };
            let behind = self.delayed.back().map(|(_, at)| *at);
            if wait.is_zero() && behind.is_none() {
                if let Err(e) = send(port, reply, idle, self.options).await {
                    return Some(Err(e));
                }
                continue;
            }
            // A delay too long to add to an instant never ends: the reply is as good as dropped.
            let Some(at) = tokio::time::Instant::now().checked_add(wait) else {
                self.options.observe(ServerEvent::Dropped { frame: reply.frame });
                continue;
            };
            self.delayed.push_back((reply, behind.map_or(at, |behind| behind.max(at))));
        }
        // The replies to the requests before a bad header have gone; nothing after it is
        // executed.
        engine.closed().map(|closed| Err(close_error(closed)))
    }

    fn deadline(&mut self, _engine: &Slave<F>) -> Option<tokio::time::Instant> {
        self.delayed.front().map(|(_, at)| *at)
    }

    fn on_wake(&mut self) -> Option<Self::Output> {
        self.woke = true;
        None
    }

    fn on_end(&mut self, error: Option<io::Error>) -> Self::Output {
        error.map_or(Ok(()), Err)
    }
}

/// Answers, one call each, the requests `slave` hands out: a request `authorize` refuses is
/// answered with its exception (a broadcast not at all) and never reaches `service`.
pub(crate) fn answer_requests<F: Framing, S: Service + ?Sized>(
    slave: &mut Slave<F>,
    service: &mut S,
    authorize: &mut Option<Box<dyn Authorize>>,
) {
    while let Some(request) = slave.poll_request() {
        let (id, broadcast) = (request.id, request.broadcast);
        let refused = authorize.as_mut().and_then(|a| a.authorize(request.unit, request.pdu).err());
        match refused {
            // The id was just handed out: it is known.
            Some(_) if broadcast => drop(slave.ignore(id)),
            Some(code) => drop(slave.refuse(id, code)),
            None => service.answer(slave, id),
        }
    }
}

/// Reports the engine's events and notes what each reply to come answers.
fn take_events<F: Framing>(engine: &mut Slave<F>, answering: &mut VecDeque<Answering>, options: &mut ServerOptions) {
    while let Some(event) = engine.poll_event() {
        if let Some(request) = Answering::of(&event) {
            if answering.len() == ANSWERING_MAX {
                answering.pop_front();
            }
            answering.push_back(request);
        }
        options.observe(ServerEvent::Slave { event, at: tokio::time::Instant::now() });
    }
}

/// A reply on its way out.
struct Outgoing {
    frame: Vec<u8>,
    /// When the engine had it due.
    due: tokio::time::Instant,
    /// Written byte by byte with this gap ([`Fate::Trickle`]), or whole.
    gap: Option<Duration>,
}

/// Writes `reply` within `idle` and reports it.
async fn send(
    port: &mut BoxPort,
    reply: Outgoing,
    idle: Option<Duration>,
    options: &mut ServerOptions,
) -> io::Result<()> {
    let at = tokio::time::Instant::now();
    let (rs485, timing) = (options.rs485, options.timing);
    match reply.gap {
        None => write(port, &reply.frame, idle, rs485, timing).await?,
        Some(gap) => {
            for (i, byte) in reply.frame.iter().enumerate() {
                if i > 0 {
                    tokio::time::sleep(gap).await;
                }
                write(port, std::slice::from_ref(byte), idle, rs485, timing).await?;
            }
        }
    }
    options.observe(ServerEvent::Sent { frame: reply.frame, due: reply.due, at });
    Ok(())
}

/// Writes `frame`; a write that does not finish within the idle timeout (a peer that reads
/// nothing) fails.
async fn write(
    port: &mut BoxPort,
    frame: &[u8],
    idle_timeout: Option<Duration>,
    rs485: Rs485,
    timing: LineTiming,
) -> io::Result<()> {
    match idle_timeout {
        Some(d) => tokio::time::timeout(d, write_frame(port, frame, rs485, &timing))
            .await
            .unwrap_or_else(|_| Err(close_error(Closed::Idle(d)))),
        None => write_frame(port, frame, rs485, &timing).await,
    }
}

/// Runs a slave engine for `config` over `port` with the framing and timing of `transport`,
/// answering through `service`, until the port fails or closes.
pub async fn serve_transport<S: Service + ?Sized>(
    transport: &Transport,
    port: BoxPort,
    config: SlaveConfig,
    service: &mut S,
    options: &mut ServerOptions,
) -> io::Result<()> {
    // A server's MBAP receiver is strict: a stream whose framing is lost is closed.
    let codec = Codec::for_transport(transport, Role::Server);
    serve(Slave::new(codec, config), port, service, options).await.1
}

/// Serves Modbus/TCP (or RTU over TCP, per `transport`'s framing) on `listener` with the
/// default [`TcpLimits`]; see [`serve_tcp_with`].
pub async fn serve_tcp<H, O>(
    listener: TcpListener,
    transport: Transport,
    config: SlaveConfig,
    handler: Shared<H>,
    options: O,
) -> io::Result<()>
where
    H: Handler + Send + 'static,
    O: Fn() -> ServerOptions + Send + Sync + 'static,
{
    serve_tcp_with(listener, TcpServeConfig::new(transport, config), handler, options).await
}

/// What a TCP server serves: its connections' framing, its slave engines' settings and the
/// listener's limits.
#[derive(Clone, Debug)]
pub struct TcpServeConfig {
    /// Modbus/TCP, or RTU over TCP: the framing of every connection.
    pub transport: Transport,
    /// The settings of each connection's slave engine.
    pub slave: SlaveConfig,
    /// Connection caps and timeouts.
    pub limits: TcpLimits,
}

impl TcpServeConfig {
    /// `transport`'s framing and `slave`'s settings, within the default [`TcpLimits`].
    pub fn new(transport: Transport, slave: SlaveConfig) -> Self {
        TcpServeConfig { transport, slave, limits: TcpLimits::default() }
    }
}

/// Serves Modbus/TCP (or RTU over TCP, per the transport's framing) on `listener`: one engine
/// per connection, all sharing `handler`, each with the options `options` makes, within the
/// limits of `serve`. No error of a connection or of accepting one ends it: it runs until
/// dropped.
pub async fn serve_tcp_with<H, O>(
    listener: TcpListener,
    serve: TcpServeConfig,
    handler: Shared<H>,
    options: O,
) -> io::Result<()>
where
    H: Handler + Send + 'static,
    O: Fn() -> ServerOptions + Send + Sync + 'static,
{
    let TcpServeConfig { transport, slave: config, limits } = serve;
    let options = Arc::new(options);
    let connection = limits.connection;
    accept_connections(listener, &limits, move |stream, _peer| {
        let transport = transport.clone();
        let mut handler = handler.clone();
        let options = Arc::clone(&options);
        async move {
            let mut options = options();
            options.connection = options.connection.or(Some(connection));
            serve_transport(&transport, Box::new(stream), config, &mut handler, &mut options).await
        }
    })
    .await
}
