//! The reverse gateway: a slave on the serial line for the units listed, forwarding each
//! request to the Modbus/TCP server that unit stands for, so that a serial PLC master reaches
//! TCP devices.
//!
//! The serial side is the slave engine, deferred, on the one driver loop (the pump): the RTU
//! codec finds frames by length first and by t3.5 second, the engine admits each request
//! for a listed unit and hands it out, and the TCP server's answer comes back into it. The
//! line is read all the while; the master waits for one reply at a time, and the engine's
//! serial rule answers one at a time (a request sent while one is forwarded gets none).
//! Requests are forwarded one at a time, in the order they came. A reply goes out no
//! earlier than t3.5 after the request's last character — the engine's timing, the same as
//! every server's — through the one RS-485-aware writer. A request for a unit not listed, a
//! frame that can only be another slave's reply, and a broadcast get no reply (a broadcast
//! write is forwarded to every server). When the TCP side gives no answer —
//! a timeout, a refused connection — the line gets silence or, with
//! [`OnFailure::Exception`], 0x0B (0x0A when the server cannot be reached at all).

use std::collections::{BTreeMap, VecDeque};
use std::future::Future;
use std::io;
use std::pin::Pin;
use std::time::Duration;

use ferrobus_proto::master::MAX_TX_LEN;
use ferrobus_proto::pdu::Request;
use ferrobus_proto::slave::{RequestId, Slave, SlaveConfig};
use ferrobus_proto::{ExceptionCode, FunctionCode};

use super::back::exception;
use crate::port::{BoxPort, Transport};
use crate::pump::{Codec, Hex, Pump, Role, Step, write_frame};
use crate::{Client, Error};

/// What the line gets when the TCP server gives no answer.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub enum OnFailure {
    /// Nothing: the serial master times out, as with a dead device.
    #[default]
    Silent,
    /// Exception 0x0B (0x0A when the server cannot be reached).
    Exception,
}

/// The TCP server one serial unit stands for.
#[derive(Clone, Debug)]
pub struct Upstream {
    /// A client of the server.
    pub client: Client,
    /// The unit id to ask it for.
    pub unit: u8,
}

/// Serves the units of `upstreams` on `port` (a serial line with `transport`'s framing and
/// timing) until the port fails or closes.
pub async fn serve_reverse(
    transport: &Transport,
    mut port: BoxPort,
    upstreams: &BTreeMap<u8, Upstream>,
    on_failure: OnFailure,
) -> io::Result<()> {
    let config = SlaveConfig { units: upstreams.keys().copied().collect(), response_wait: Duration::ZERO };
    let mut slave = Slave::new(Codec::for_transport(transport, Role::Server), config);
    // The TCP side's client has its own timeout; the engine waits for its word.
    slave.set_answer_limit(None);
    let mut pump = Pump::new(transport.timer().sleeper());
    let (rs485, timing) = (transport.rs485(), *transport.timing());
    let mut tx = [0u8; MAX_TX_LEN];
    // The forwards under way, oldest first, one at a time: each with the request it answers
    // (none for a broadcast, finished at once: it gets no reply).
    let mut forwards: VecDeque<(Option<RequestId>, Forward<'_>)> = VecDeque::new();
    loop {
        while let Some(n) = slave.poll_transmit(pump.clock().now(), &mut tx) {
            write_frame(&mut port, tx.get(..n).unwrap_or_default(), rs485, &timing).await?;
        }
        while let Some(event) = slave.poll_event() {
            tracing::debug!("{event:?}");
        }
        while let Some(request) = slave.poll_request() {
            let (id, unit, pdu) = (request.id, request.unit, request.pdu.to_vec());
            if request.broadcast {
                // Executed as far as the line can tell (no reply); forwarded behind what came
                // before.
                let _ = slave.respond(id, &pdu);
                forwards.push_back((None, Box::pin(broadcast(upstreams, pdu))));
            } else {
                forwards.push_back((Some(id), Box::pin(forward(upstreams, unit, pdu, on_failure))));
            }
        }
        if pump.feed_kept(&mut slave) {
            continue;
        }
        let deadline = pump.deadline(&slave);
        let answer = async {
            match forwards.front_mut() {
                Some((_, forward)) => forward.as_mut().await,
                None => std::future::pending().await,
            }
        };
        // The line is read while a forward is under way: the engine keeps the request's slot
        // and its timing, and stays silent on a master that does not wait.
        match pump.step(&mut port, &mut slave, deadline, answer).await {
            Step::Read => {}
            Step::Closed => return Ok(()),
            Step::Failed(e) => return Err(e),
            Step::Woke => pump.handle_timeout(&mut slave),
            Step::Other(reply) => {
                let Some((id, _)) = forwards.pop_front() else { continue };
                let Some(id) = id else { continue };
                // The engine gives no limit, so the id is still known.
                let _ = match reply {
                    Some(pdu) => {
                        tracing::info!("reply {}", Hex(&pdu));
                        slave.respond(id, &pdu)
                    }
                    None => slave.ignore(id),
                };
            }
        }
    }
}

/// One forward to the TCP side: the reply for the line, if any.
type Forward<'a> = Pin<Box<dyn Future<Output = Option<Vec<u8>>> + Send + 'a>>;

/// A broadcast write, to every server; nothing comes back to the line.
async fn broadcast(upstreams: &BTreeMap<u8, Upstream>, pdu: Vec<u8>) -> Option<Vec<u8>> {
    let function = pdu.first().copied().unwrap_or_default();
    if FunctionCode::from_u8(function).is_write() {
        for upstream in upstreams.values() {
            if let Err(e) = upstream.client.raw(upstream.unit, &pdu).await {
                tracing::info!("broadcast to unit {}: {e}", upstream.unit);
            }
        }
    }
    None
}

/// The reply for the line, if any.
async fn forward(upstreams: &BTreeMap<u8, Upstream>, unit: u8, pdu: Vec<u8>, on_failure: OnFailure) -> Option<Vec<u8>> {
    let pdu = pdu.as_slice();
    let function = pdu.first().copied().unwrap_or_default();
    let upstream = upstreams.get(&unit)?;
    tracing::info!(unit, "request {}", Hex(pdu));
    let result = match Request::parse(pdu) {
        Ok(request) => upstream.client.request(upstream.unit, &request).await,
        Err(_) => upstream.client.raw(upstream.unit, pdu).await,
    };
    match result {
        Ok(reply) => reply,
        Err(Error::Exception { code, .. }) => Some(exception(function, code.value())),
        Err(e) => {
            tracing::info!(unit, "no answer from the TCP side: {e}");
            let code = match e {
                Error::Timeout { .. } | Error::BadReply { .. } | Error::Backoff { .. } => {
                    ExceptionCode::GatewayTargetDeviceFailedToRespond
                }
                _ => ExceptionCode::GatewayPathUnavailable,
            };
            (on_failure == OnFailure::Exception).then(|| exception(function, code.value()))
        }
    }
}
