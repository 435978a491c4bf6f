//! One client connection of the gateway: frames in, each request authorized, routed and
//! queued for its line, replies out in the order the requests came.
//!
//! The connection is generic over its stream, so a TLS stream is served by the same code as
//! plain TCP. It keeps the hardened server's rules: a strict MBAP receiver (a bad header
//! closes the connection: the stream's framing is lost), an idle timeout while nothing is
//! outstanding, a timeout on a frame begun and never finished, and at most
//! [`Timeouts::pipeline`] requests outstanding — past it the socket is not read, so a client
//! that floods is held back by TCP instead of filling the lines' queues.

use std::collections::VecDeque;
use std::io;

use ferrobus_proto::error::DiscardReason;
use ferrobus_proto::frame::{AduHeader, Framing, RxEvent, feed};
use ferrobus_proto::{ExceptionCode, FunctionCode};
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::sync::oneshot;

use super::line::{Job, exception};
use super::{Authorize, Inbound, Inner, Timeouts};
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
    let connection = gateway.next_connection();
    let mut codec = Codec::for_transport(&inbound.transport(), Role::Server);
    let clock = Clock::new();
    let mut pending: VecDeque<Slot> = VecDeque::new();
    let mut rx = vec![0u8; 1024];
    let mut tx = [0u8; 300];
    let mut last_activity = tokio::time::Instant::now();
    let mut frame_began: Option<tokio::time::Instant> = None;
    loop {
        // Replies go out in request order, as soon as the first is there.
        while let Some(slot) = pending.front() {
            let State::Ready(pdu) = &slot.state else { break };
            let n = codec
                .encode(slot.header, pdu, &mut tx)
                .map_err(|e| io::Error::new(io::ErrorKind::InvalidData, format!("reply too long: {e:?}")))?;
            let frame = tx.get(..n).unwrap_or_default();
            tracing::info!(%peer, unit = slot.header.unit, transaction = slot.header.transaction, "reply {}", Hex(pdu));
            write(&mut stream, frame, timeouts).await?;
            last_activity = tokio::time::Instant::now();
            pending.pop_front();
        }
        frame_began = if codec.is_mid_frame() { frame_began.or(Some(last_activity)) } else { None };
        let idle_at = timeouts.idle.filter(|_| pending.is_empty()).and_then(|d| last_activity.checked_add(d));
        let unfinished_at = timeouts.frame.zip(frame_began).and_then(|(d, began)| began.checked_add(d));
        let deadline =
            [codec.poll_timeout().map(|t| clock.to_tokio(t)), idle_at, unfinished_at].into_iter().flatten().min();
        let reading = pending.len() < timeouts.pipeline.max(1);
        let woke = {
            let front = async {
                match pending.front_mut().map(|s| &mut s.state) {
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
        let mut lost = false;
        match woke {
            Woke::Read(Ok(0)) => return Ok(()),
            Woke::Read(Err(e)) => return Err(e),
            Woke::Read(Ok(n)) => {
                last_activity = tokio::time::Instant::now();
                let bytes = rx.get(..n).unwrap_or_default();
                tracing::trace!(%peer, "rx {}", Hex(bytes));
                feed(&mut codec, clock.now(), bytes, |event| {
                    lost |= on_event(gateway, connection, peer, authorize, &mut pending, lost, &event);
                });
            }
            Woke::Reply(reply) => settle_front(&mut pending, reply),
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
                    lost |= on_event(gateway, connection, peer, authorize, &mut pending, lost, &event);
                }
            }
        }
        if lost {
            // Nothing after a bad header is executed; what came before is still answered.
            answer_all(&mut stream, &codec, pending, timeouts).await?;
            return Err(Closed::BadHeader.error());
        }
    }
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

/// Handles one receiver event; returns whether the stream's framing is lost.
fn on_event(
    gateway: &Inner,
    connection: u64,
    peer: &str,
    authorize: &mut dyn Authorize,
    pending: &mut VecDeque<Slot>,
    lost: bool,
    event: &RxEvent<'_>,
) -> bool {
    let frame = match *event {
        RxEvent::Frame(frame) => frame,
        RxEvent::Discarded { bytes, reason, .. } => {
            tracing::info!(%peer, "discarded {bytes} bytes: {reason:?}");
            return reason == DiscardReason::BadHeader;
        }
    };
    if lost {
        return true;
    }
    let (header, pdu) = (frame.header, frame.pdu);
    tracing::info!(%peer, unit = header.unit, transaction = header.transaction, "request {}", Hex(pdu));
    let function = pdu.first().copied().unwrap_or_default();
    let refuse =
        |code: ExceptionCode| Slot { header, echo: None, state: State::Ready(exception(function, code.value())) };
    if let Err(code) = authorize.authorize(header.unit, pdu) {
        tracing::info!(%peer, unit = header.unit, "refused function {function:#04x}: exception {code}");
        pending.push_back(refuse(code));
        return false;
    }
    // Unit 0: Modbus/TCP has no broadcast of its own, but a client of a gateway to a
    // serial line means the line's broadcast by it.
    if header.unit == 0 {
        if !FunctionCode::from_u8(function).is_write() {
            // No device answers a broadcast: there is no path to a reply for a read.
            pending.push_back(refuse(ExceptionCode::GatewayPathUnavailable));
            return false;
        }
        if let Some(slot) = gateway.broadcast(connection, header, pdu) {
            pending.push_back(slot_waiting(header, Some(pdu.to_vec()), slot));
        }
        return false;
    }
    let Some(route) = gateway.routes.get(header.unit) else {
        pending.push_back(refuse(ExceptionCode::GatewayPathUnavailable));
        return false;
    };
    if let Some(pdu) = gateway.cached(header.unit, pdu) {
        pending.push_back(Slot { header, echo: None, state: State::Ready(pdu) });
        return false;
    }
    let (reply, rx) = oneshot::channel();
    let job = Job { unit_in: header.unit, unit_out: route.unit, pdu: pdu.to_vec(), reply };
    match gateway.submit(route.line, connection, job) {
        Ok(()) => pending.push_back(slot_waiting(header, None, rx)),
        Err(()) => pending.push_back(refuse(ExceptionCode::ServerDeviceBusy)),
    }
    false
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
