//! One client connection of the gateway: frames in, each request checked, authorized,
//! routed and queued for its line, replies out in the order the requests came.
//!
//! The connection is generic over its stream, so a TLS stream is served by the same code as
//! plain TCP. It keeps the hardened server's rules: a strict MBAP receiver (a bad header
//! closes the connection: the stream's framing is lost), an idle timeout while nothing is
//! outstanding, a timeout on a frame begun and never finished, and at most
//! [`Timeouts::pipeline`] requests outstanding. The bound holds frame by frame: bytes read
//! are framed only while there is room for another request, and the socket is read again
//! only once every byte read has been framed — so a client that floods (one read may hold a
//! hundred requests) is held back by TCP instead of filling the lines' queues.
//!
//! Every request is checked first ([`screen`](super::screen)): one that no device could take
//! is answered at once and reaches no line.

use std::collections::VecDeque;
use std::io;

use ferrobus_proto::Instant;
use ferrobus_proto::error::DiscardReason;
use ferrobus_proto::frame::{AduHeader, Framing, RxEvent};
use ferrobus_proto::{ExceptionCode, FunctionCode};
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::sync::oneshot;

use super::line::{Job, exception};
use super::{Authorize, Inbound, Inner, Timeouts, screen};
use crate::clock::Clock;
use crate::pump::{Codec, Hex, Role};
use crate::server::Closed;

/// A reply to come, in request order.
struct Slot {
    header: AduHeader,
    /// What answers a broadcast that completes (`--broadcast-ack`: the request itself).
    echo: Option<Vec<u8>>,
    state: State,
}

enum State {
    Ready(Vec<u8>),
    Waiting(oneshot::Receiver<Option<Vec<u8>>>),
}

/// What woke the connection.
enum Woke {
    Read(io::Result<usize>),
    Reply(Result<Option<Vec<u8>>, oneshot::error::RecvError>),
    Deadline,
}

/// Serves one connection until the client closes it or it is closed for cause.
pub(crate) async fn serve<S>(
    gateway: &Inner,
    mut stream: S,
    peer: &str,
    inbound: Inbound,
    authorize: &mut dyn Authorize,
    timeouts: Timeouts,
) -> io::Result<()>
where
    S: AsyncRead + AsyncWrite + Unpin + Send,
{
    let mut codec = Codec::for_transport(&inbound.transport(), Role::Server);
    let clock = Clock::new();
    let mut requests = Requests {
        gateway,
        connection: gateway.next_connection(),
        peer,
        authorize,
        pending: VecDeque::new(),
        lost: false,
    };
    let pipeline = timeouts.pipeline.max(1);
    let mut unread = Unread::default();
    let mut rx = vec![0u8; 1024];
    let mut last_activity = tokio::time::Instant::now();
    let mut frame_began: Option<tokio::time::Instant> = None;
    loop {
        // Frame what was read while there is room for another request, and send the replies
        // that are there, in request order, until neither makes progress: a reply sent makes
        // room for the next request read.
        loop {
            requests.frame(&mut codec, &mut unread, clock.now(), pipeline);
            if requests.lost {
                // Nothing after a bad header is executed; what came before is still answered.
                answer_all(&mut stream, &codec, requests.pending, timeouts).await?;
                return Err(Closed::BadHeader.error());
            }
            if !send_ready(&mut stream, &codec, &mut requests.pending, peer, timeouts).await? {
                break;
            }
            last_activity = tokio::time::Instant::now();
        }
        // Read, and run the receiver's and the client's clocks, only with room for a request
        // and every byte read framed: the client waits on the gateway, not the other way round.
        let reading = requests.pending.len() < pipeline && unread.bytes.is_empty();
        frame_began = if reading && codec.is_mid_frame() { frame_began.or(Some(last_activity)) } else { None };
        let idle_at = timeouts.idle.filter(|_| requests.pending.is_empty()).and_then(|d| last_activity.checked_add(d));
        let unfinished_at = timeouts.frame.zip(frame_began).and_then(|(d, began)| began.checked_add(d));
        let gap_at = codec.poll_timeout().filter(|_| reading).map(|t| clock.to_tokio(t));
        let deadline = [gap_at, idle_at, unfinished_at].into_iter().flatten().min();
        let woke = {
            let front = async {
                match requests.pending.front_mut().map(|s| &mut s.state) {
                    Some(State::Waiting(rx)) => rx.await,
                    _ => std::future::pending().await,
                }
            };
            let sleep = async {
                match deadline {
                    Some(at) => tokio::time::sleep_until(at).await,
                    None => std::future::pending().await,
                }
            };
            tokio::select! {
                read = stream.read(&mut rx), if reading => Woke::Read(read),
                reply = front => Woke::Reply(reply),
                () = sleep => Woke::Deadline,
            }
        };
        match woke {
            Woke::Read(Ok(0)) => return Ok(()),
            Woke::Read(Err(e)) => return Err(e),
            Woke::Read(Ok(n)) => {
                last_activity = tokio::time::Instant::now();
                let bytes = rx.get(..n).unwrap_or_default();
                tracing::trace!(%peer, "rx {}", Hex(bytes));
                unread.arrived(clock.now(), bytes);
            }
            Woke::Reply(reply) => settle_front(&mut requests.pending, reply),
            Woke::Deadline => {
                let now = tokio::time::Instant::now();
                if let Some(d) = timeouts.idle.filter(|_| idle_at.is_some_and(|at| now >= at)) {
                    return Err(Closed::Idle(d).error());
                }
                if let Some(d) = timeouts.frame.filter(|_| unfinished_at.is_some_and(|at| now >= at)) {
                    return Err(Closed::UnfinishedFrame(d).error());
                }
                codec.handle_timeout(clock.now());
                while let Some(event) = codec.poll_event() {
                    requests.on_event(&event);
                }
            }
        }
    }
}

/// Bytes read from the socket and not yet framed, with when they arrived.
#[derive(Default)]
struct Unread {
    bytes: Vec<u8>,
    at: Option<Instant>,
}

impl Unread {
    /// Keeps `bytes`, read at `now` (the socket is read only once the last are framed).
    fn arrived(&mut self, now: Instant, bytes: &[u8]) {
        self.bytes.extend_from_slice(bytes);
        self.at = Some(now);
    }
}

/// The connection's requests: what checks, routes and queues each one, and the replies to
/// come in request order.
struct Requests<'a> {
    gateway: &'a Inner,
    connection: u64,
    peer: &'a str,
    authorize: &'a mut dyn Authorize,
    pending: VecDeque<Slot>,
    /// The stream's framing is lost (a bad MBAP header): nothing more is executed.
    lost: bool,
}

impl Requests<'_> {
    /// Pushes the unread bytes (and any frames the receiver holds already) into `codec`, one
    /// frame at a time, until every byte is framed or `pipeline` requests are outstanding.
    /// Bytes are pushed at the time they arrived, so that a serial framing's gaps stay
    /// true however long they waited.
    fn frame(&mut self, codec: &mut Codec, unread: &mut Unread, now: Instant, pipeline: usize) {
        while self.pending.len() < pipeline && !self.lost {
            let at = if unread.bytes.is_empty() { now } else { unread.at.unwrap_or(now) };
            let consumed = codec.push(at, &unread.bytes).min(unread.bytes.len());
            unread.bytes.drain(..consumed);
            let mut any = false;
            while let Some(event) = codec.poll_event() {
                self.on_event(&event);
                any = true;
            }
            if !any && (unread.bytes.is_empty() || consumed == 0) {
                break;
            }
        }
    }

    /// Handles one receiver event; a bad header marks the stream's framing lost.
    fn on_event(&mut self, event: &RxEvent<'_>) {
        let peer = self.peer;
        let frame = match *event {
            RxEvent::Frame(frame) => frame,
            RxEvent::Discarded { bytes, reason, .. } => {
                tracing::info!(%peer, "discarded {bytes} bytes: {reason:?}");
                self.lost |= reason == DiscardReason::BadHeader;
                return;
            }
        };
        if self.lost {
            return;
        }
        let (header, pdu) = (frame.header, frame.pdu);
        tracing::info!(%peer, unit = header.unit, transaction = header.transaction, "request {}", Hex(pdu));
        let slot = self.admit(header, pdu);
        self.pending.extend(slot);
    }

    /// What answers the request `pdu` for `header`: a reply ready at once (a refusal, the
    /// cache) or one to wait for; `None` for a broadcast that gets no reply.
    fn admit(&mut self, header: AduHeader, pdu: &[u8]) -> Option<Slot> {
        let (gateway, peer) = (self.gateway, self.peer);
        let function = pdu.first().copied().unwrap_or_default();
        let refuse = |code: ExceptionCode| {
            Some(Slot { header, echo: None, state: State::Ready(exception(function, code.value())) })
        };
        if let Err(refused) = screen::check(pdu) {
            tracing::info!(%peer, unit = header.unit, "refused function {function:#04x} ({}): exception {}", refused.reason, refused.code);
            gateway.front().count(refused.reason);
            return refuse(refused.code);
        }
        if let Err(code) = self.authorize.authorize(header.unit, pdu) {
            tracing::info!(%peer, unit = header.unit, "refused function {function:#04x}: exception {code}");
            return refuse(code);
        }
        // Unit 0: Modbus/TCP has no broadcast of its own, but a client of a gateway to a
        // serial line means the line's broadcast by it.
        if header.unit == 0 {
            if !FunctionCode::from_u8(function).is_write() {
                // No device answers a broadcast: there is no path to a reply for a read.
                return refuse(ExceptionCode::GatewayPathUnavailable);
            }
            let done = gateway.broadcast(self.connection, header, pdu)?;
            return Some(slot_waiting(header, Some(pdu.to_vec()), done));
        }
        let Some(route) = gateway.routes.get(header.unit) else {
            return refuse(ExceptionCode::GatewayPathUnavailable);
        };
        if let Some(pdu) = gateway.cached(header.unit, pdu) {
            return Some(Slot { header, echo: None, state: State::Ready(pdu) });
        }
        let (reply, rx) = oneshot::channel();
        let job = Job { unit_in: header.unit, unit_out: route.unit, pdu: pdu.to_vec(), reply };
        match gateway.submit(route.line, self.connection, job) {
            Ok(()) => Some(slot_waiting(header, None, rx)),
            Err(()) => refuse(ExceptionCode::ServerDeviceBusy),
        }
    }
}

/// Sends the replies at the front that are ready, in order; returns whether any went out.
async fn send_ready<S: AsyncWrite + Unpin>(
    stream: &mut S,
    codec: &Codec,
    pending: &mut VecDeque<Slot>,
    peer: &str,
    timeouts: Timeouts,
) -> io::Result<bool> {
    let mut tx = [0u8; 300];
    let mut sent = false;
    while let Some(slot) = pending.front() {
        let State::Ready(pdu) = &slot.state else { break };
        let n = codec
            .encode(slot.header, pdu, &mut tx)
            .map_err(|e| io::Error::new(io::ErrorKind::InvalidData, format!("reply too long: {e:?}")))?;
        tracing::info!(%peer, unit = slot.header.unit, transaction = slot.header.transaction, "reply {}", Hex(pdu));
        write(stream, tx.get(..n).unwrap_or_default(), timeouts).await?;
        pending.pop_front();
        sent = true;
    }
    Ok(sent)
}

/// The front slot's reply has come: it is ready (a broadcast without an echo is dropped).
fn settle_front(pending: &mut VecDeque<Slot>, reply: Result<Option<Vec<u8>>, oneshot::error::RecvError>) {
    if let Some(slot) = pending.front_mut() {
        let function = slot.echo.as_ref().and_then(|e| e.first().copied()).unwrap_or_default();
        slot.state = State::Ready(match reply {
            Ok(Some(pdu)) => pdu,
            // A broadcast done: the echo, where one was asked for.
            Ok(None) => slot.echo.take().unwrap_or_default(),
            // The line's worker has gone (the gateway is stopping).
            Err(_) => exception(function, ExceptionCode::GatewayPathUnavailable.value()),
        });
    }
    pending.retain(|s| !matches!(&s.state, State::Ready(pdu) if pdu.is_empty()));
}

/// Waits for and writes every reply still to come, in order.
async fn answer_all<S: AsyncWrite + Unpin>(
    stream: &mut S,
    codec: &Codec,
    pending: VecDeque<Slot>,
    timeouts: Timeouts,
) -> io::Result<()> {
    let mut tx = [0u8; 300];
    for slot in pending {
        let pdu = match slot.state {
            State::Ready(pdu) => pdu,
            State::Waiting(rx) => match rx.await {
                Ok(Some(pdu)) => pdu,
                Ok(None) => slot.echo.unwrap_or_default(),
                Err(_) => continue,
            },
        };
        if pdu.is_empty() {
            continue;
        }
        if let Ok(n) = codec.encode(slot.header, &pdu, &mut tx) {
            write(stream, tx.get(..n).unwrap_or_default(), timeouts).await?;
        }
    }
    Ok(())
}

fn slot_waiting(header: AduHeader, echo: Option<Vec<u8>>, rx: oneshot::Receiver<Option<Vec<u8>>>) -> Slot {
    Slot { header, echo, state: State::Waiting(rx) }
}

/// Writes `frame`; a write that does not finish within the idle timeout (a peer that reads
/// nothing) fails.
async fn write<S: AsyncWrite + Unpin>(stream: &mut S, frame: &[u8], timeouts: Timeouts) -> io::Result<()> {
    let write = async {
        stream.write_all(frame).await?;
        stream.flush().await
    };
    match timeouts.idle {
        Some(d) => tokio::time::timeout(d, write).await.unwrap_or_else(|_| Err(Closed::Idle(d).error())),
        None => write.await,
    }
}
