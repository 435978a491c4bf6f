//! One client connection of the gateway: frames in, each request checked, authorized,
//! routed and queued for its line, replies out in the order the requests came.
//!
//! The connection runs on the one driver loop (the pump) with the slave engine, deferred:
//! the engine frames and admits each request and hands it out, the front sends it to its
//! line's queue, and the line's reply comes back into the engine ([`Slave::respond`]), which
//! sends the replies in request order. The connection is generic over its stream, so a TLS
//! stream is served by the same code as plain TCP. It keeps the hardened server's rules: a
//! strict MBAP receiver (a bad header closes the connection: the stream's framing is lost),
//! and the connection's [`ConnectionPolicy`], which the engine applies on its own time (an
//! idle timeout while nothing is outstanding, a timeout on a frame begun and never finished,
//! at most [`ConnectionPolicy::max_pending`] requests outstanding; [`Slave::closed`] says when
//! it is done with the connection). The bound holds frame by frame: the engine frames bytes only
//! while there is room for another request, and the socket is read again only once every
//! byte read has been framed — so a client that floods (one read may hold a hundred requests)
//! is held back by TCP instead of filling the lines' queues.
//!
//! Every request is checked first ([`screen`](super::screen)): one that no device could take
//! is answered at once and reaches no line.

use std::collections::VecDeque;
use std::io;
use std::time::Duration;

use ferrobus_proto::frame::{AduHeader, Framing};
use ferrobus_proto::master::MAX_TX_LEN;
use ferrobus_proto::slave::{RequestId, Slave, SlaveConfig, SlaveEvent, UnitSet};
use ferrobus_proto::{ExceptionCode, FunctionCode};
use tokio::io::{AsyncRead, AsyncWrite, AsyncWriteExt};
use tokio::sync::oneshot;

use super::back::{Job, exception};
use super::{Authorize, Inbound, Inner, screen};
use ferrobus::log::Hex;
use ferrobus::port::{BoxPort, Port};
use ferrobus::pump::{Codec, Pump, Role, Session};
use ferrobus::server::{Closed, ConnectionPolicy, close_error};
use ferrobus::timer::Timer;

/// A request sent to a line (or to every line), waiting for its reply.
struct Waiting {
    id: RequestId,
    /// The request's function code (for the exception if the line's worker has gone).
    function: u8,
    /// What answers a broadcast that completes (`--broadcast-ack`: the request itself).
    echo: Option<Vec<u8>>,
    reply: oneshot::Receiver<Option<Vec<u8>>>,
    /// The reply, once it has come.
    settled: Option<Result<Option<Vec<u8>>, oneshot::error::RecvError>>,
}

/// Serves one connection until the client closes it or it is closed for cause.
pub(crate) async fn serve<S>(
    gateway: &Inner,
    stream: S,
    peer: &str,
    inbound: Inbound,
    authorize: &mut dyn Authorize,
    connection: ConnectionPolicy,
) -> io::Result<()>
where
    S: AsyncRead + AsyncWrite + Unpin + Send + 'static,
{
    let mut port: BoxPort = Box::new(Stream(stream));
    // Every unit is heard: the routes decide, and unit 0 is the front's own business.
    let config = SlaveConfig { units: (0..=u8::MAX).collect::<UnitSet>(), response_wait: Duration::ZERO };
    let mut slave = Box::new(Slave::new(Codec::for_transport(&inbound.transport(), Role::Server), config));
    slave.set_stream(true);
    // Every line job is answered (its worker times the device out), or its channel closes.
    slave.set_answer_limit(None);
    let mut pump = Pump::new(Timer::Tokio.sleeper());
    slave.set_connection_policy(connection, pump.clock().now());
    let mut front = Box::new(Front {
        gateway,
        connection: gateway.next_connection(),
        peer,
        authorize,
        waiting: VecDeque::new(),
        tx: [0u8; MAX_TX_LEN],
    });
    pump.run(&mut port, &mut *slave, &mut *front).await
}

/// The client's stream as a port of the pump.
struct Stream<S>(S);

impl<S: AsyncRead + Unpin> AsyncRead for Stream<S> {
    fn poll_read(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
        buf: &mut tokio::io::ReadBuf<'_>,
    ) -> std::task::Poll<io::Result<()>> {
        std::pin::Pin::new(&mut self.0).poll_read(cx, buf)
    }
}

impl<S: AsyncWrite + Unpin> AsyncWrite for Stream<S> {
    fn poll_write(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
        buf: &[u8],
    ) -> std::task::Poll<io::Result<usize>> {
        std::pin::Pin::new(&mut self.0).poll_write(cx, buf)
    }
    fn poll_flush(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
    ) -> std::task::Poll<io::Result<()>> {
        std::pin::Pin::new(&mut self.0).poll_flush(cx)
    }
    fn poll_shutdown(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
    ) -> std::task::Poll<io::Result<()>> {
        std::pin::Pin::new(&mut self.0).poll_shutdown(cx)
    }
}

impl<S: AsyncRead + AsyncWrite + Unpin + Send + 'static> Port for Stream<S> {}

/// The connection's session around the pump: what checks, routes and queues each request
/// the engine hands out, brings the lines' replies back into it, writes what it sends, and
/// closes the connection when the engine is done with it.
struct Front<'a> {
    gateway: &'a Inner,
    connection: u64,
    peer: &'a str,
    authorize: &'a mut dyn Authorize,
    /// The requests sent to a line, oldest first.
    waiting: VecDeque<Waiting>,
    tx: [u8; MAX_TX_LEN],
}

impl<F: Framing> Session<Slave<F>> for Front<'_> {
    type Output = io::Result<()>;

    async fn serve(&mut self, pump: &Pump, port: &mut BoxPort, engine: &mut Slave<F>) -> Option<Self::Output> {
        if let Some(closed @ (Closed::Idle(_) | Closed::UnfinishedFrame(_))) = engine.closed() {
            return Some(Err(close_error(closed)));
        }
        self.settle(engine);
        let peer = self.peer;
        while let Some(event) = engine.poll_event() {
            if let SlaveEvent::Discarded { bytes, reason, .. } = event {
                tracing::info!(%peer, "discarded {bytes} bytes: {reason:?}");
            }
        }
        // The strict receiver frames nothing after a bad header: every request handed out
        // came before it, and is still answered.
        while let Some(request) = engine.poll_request() {
            let (id, unit, pdu) = (request.id, request.unit, request.pdu.to_vec());
            tracing::info!(%peer, unit, transaction = request.transaction, "request {}", Hex(&pdu));
            self.admit(engine, id, unit, &pdu);
        }
        if let Err(e) = self.send_due(pump, port, engine).await {
            return Some(Err(e));
        }
        if engine.closed() != Some(Closed::BadHeader) {
            return None;
        }
        // Nothing after a bad header is executed; what came before is still answered.
        loop {
            if let Err(e) = self.send_due(pump, port, engine).await {
                return Some(Err(e));
            }
            if let Some(due) = engine.reply_due() {
                tokio::time::sleep_until(pump.clock().to_tokio(due)).await;
                continue;
            }
            let Some(front) = self.waiting.front_mut() else { break };
            front.settled = Some((&mut front.reply).await);
            self.settle(engine);
        }
        Some(Err(close_error(Closed::BadHeader)))
    }

    async fn wait(&mut self) {
        match self.waiting.iter_mut().find(|w| w.settled.is_none()) {
            // Cancel-safe: a receiver polled again later still holds the reply.
            Some(waiting) => waiting.settled = Some((&mut waiting.reply).await),
            None => std::future::pending().await,
        }
    }

    fn on_end(&mut self, error: Option<io::Error>) -> Self::Output {
        error.map_or(Ok(()), Err)
    }
}

impl Front<'_> {
    /// Checks, routes and queues request `id` for `unit`: answered at once (a refusal, the
    /// cache), sent to a line to wait for its reply, or finished without one (a broadcast
    /// without an echo).
    fn admit<F: Framing>(&mut self, engine: &mut Slave<F>, id: RequestId, unit: u8, pdu: &[u8]) {
        let (gateway, peer) = (self.gateway, self.peer);
        let function = pdu.first().copied().unwrap_or_default();
        let refuse = |engine: &mut Slave<F>, code: ExceptionCode| {
            // The id was just handed out: it is known.
            let _ = engine.respond(id, &exception(function, code.value()));
        };
        if let Err(refused) = screen::check(pdu) {
            tracing::info!(%peer, unit, "refused function {function:#04x} ({}): exception {}", refused.reason, refused.code);
            gateway.front().count(refused.reason);
            return refuse(engine, refused.code);
        }
        if let Err(code) = self.authorize.authorize(unit, pdu) {
            tracing::info!(%peer, unit, "refused function {function:#04x}: exception {code}");
            return refuse(engine, code);
        }
        // Unit 0: Modbus/TCP has no broadcast of its own, but a client of a gateway to a
        // serial line means the line's broadcast by it; unless it is routed (a Modbus/TCP
        // line's own unit 0, which its device may answer).
        let table = gateway.table();
        if unit == 0 && table.routes.get(0).is_none() {
            if !FunctionCode::from_u8(function).is_write() || !gateway.broadcasts() {
                // No device answers a broadcast: there is no path to a reply for a read; and
                // with no serial line there is no broadcast to send.
                return refuse(engine, ExceptionCode::GatewayPathUnavailable);
            }
            match gateway.broadcast(self.connection, AduHeader::unit(0), pdu) {
                Some(done) => self.waiting.push_back(Waiting {
                    id,
                    function,
                    echo: Some(pdu.to_vec()),
                    reply: done,
                    settled: None,
                }),
                None => drop(engine.ignore(id)),
            }
            return;
        }
        let Some(route) = table.routes.get(unit) else {
            return refuse(engine, ExceptionCode::GatewayPathUnavailable);
        };
        if let Some(cached) = gateway.cached(&table, unit, pdu) {
            return respond(engine, id, &cached);
        }
        let (reply, rx) = oneshot::channel();
        let job = Job { unit_in: unit, unit_out: route.unit, pdu: pdu.to_vec(), reply, broadcast: false };
        match table.submit(route.line, self.connection, job) {
            Ok(()) => self.waiting.push_back(Waiting { id, function, echo: None, reply: rx, settled: None }),
            Err(code) => refuse(engine, code),
        }
    }

    /// Hands the engine the replies that have come, oldest first (a broadcast done: its
    /// echo, where one was asked for, else nothing).
    fn settle<F: Framing>(&mut self, engine: &mut Slave<F>) {
        while self.waiting.front().is_some_and(|w| w.settled.is_some()) {
            let Some(waiting) = self.waiting.pop_front() else { break };
            let pdu = match waiting.settled {
                Some(Ok(Some(pdu))) => Some(pdu),
                Some(Ok(None)) => waiting.echo,
                // The line's worker has gone (the gateway is stopping).
                Some(Err(_)) | None => Some(exception(waiting.function, ExceptionCode::GatewayPathUnavailable.value())),
            };
            match pdu.filter(|p| !p.is_empty()) {
                Some(pdu) => respond(engine, waiting.id, &pdu),
                None => drop(engine.ignore(waiting.id)),
            }
        }
    }

    /// Writes the replies the engine has due, in request order.
    async fn send_due<F: Framing>(&mut self, pump: &Pump, port: &mut BoxPort, engine: &mut Slave<F>) -> io::Result<()> {
        let idle = engine.connection_policy().idle;
        while let Some(n) = engine.poll_transmit(pump.clock().now(), &mut self.tx) {
            let frame = self.tx.get(..n).unwrap_or_default();
            tracing::info!(peer = %self.peer, "reply {}", Hex(frame));
            write(port, frame, idle).await?;
        }
        Ok(())
    }
}

/// Answers request `id` with the line's `pdu`; one no PDU can be (a line's reply too long)
/// gets 0x0B instead.
fn respond<F: Framing>(engine: &mut Slave<F>, id: RequestId, pdu: &[u8]) {
    if engine.respond(id, pdu).is_err() {
        let _ = engine.refuse(id, ExceptionCode::GatewayTargetDeviceFailedToRespond);
    }
}

/// Writes `frame`; a write that does not finish within `idle` (a peer that reads nothing)
/// fails.
async fn write(port: &mut BoxPort, frame: &[u8], idle: Option<Duration>) -> io::Result<()> {
    let write = async {
        port.write_all(frame).await?;
        port.flush().await
    };
    match idle {
        Some(d) => tokio::time::timeout(d, write).await.unwrap_or_else(|_| Err(close_error(Closed::Idle(d)))),
        None => write.await,
    }
}
