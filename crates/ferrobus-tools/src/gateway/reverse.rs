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

use ferrobus_proto::FunctionCode;
use ferrobus_proto::frame::{Framing, LineTiming};
use ferrobus_proto::master::MAX_TX_LEN;
use ferrobus_proto::pdu::Request;
use ferrobus_proto::slave::{RequestId, Slave, SlaveConfig};

use ferrobus::log::Hex;
use ferrobus::port::{BoxPort, Rs485, Transport};
use ferrobus::pump::{Codec, Pump, Role, Session, write_frame};
use ferrobus::{Client, Error};

use super::back::{exception, failure};
use super::stats::Ended;

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
    let mut session = Reverse {
        upstreams,
        on_failure,
        rs485: transport.rs485(),
        timing: *transport.timing(),
        tx: [0; MAX_TX_LEN],
        forwards: VecDeque::new(),
        answered: None,
    };
    pump.run(&mut port, &mut slave, &mut session).await
}

/// The reverse gateway's session on the pump: the requests the engine admits, forwarded one
/// at a time, each answer given back to the engine.
struct Reverse<'a> {
    upstreams: &'a BTreeMap<u8, Upstream>,
    on_failure: OnFailure,
    rs485: Rs485,
    timing: LineTiming,
    tx: [u8; MAX_TX_LEN],
    /// The forwards under way, oldest first, one at a time: each with the request it answers
    /// (none for a broadcast, finished at once: it gets no reply).
    forwards: VecDeque<(Option<RequestId>, Forward<'a>)>,
    /// The oldest forward's answer, for the engine at the next turn.
    answered: Option<(RequestId, Option<Vec<u8>>)>,
}

impl<F: Framing> Session<Slave<F>> for Reverse<'_> {
    type Output = io::Result<()>;

    async fn serve(&mut self, pump: &Pump, port: &mut BoxPort, slave: &mut Slave<F>) -> Option<io::Result<()>> {
        if let Some((id, reply)) = self.answered.take() {
            // The engine gives no limit, so the id is still known.
            let _ = match reply {
                Some(pdu) => {
                    tracing::info!("reply {}", Hex(&pdu));
                    slave.respond(id, &pdu)
                }
                None => slave.ignore(id),
            };
        }
        while let Some(n) = slave.poll_transmit(pump.clock().now(), &mut self.tx) {
            let frame = self.tx.get(..n).unwrap_or_default();
            if let Err(e) = write_frame(port, frame, self.rs485, &self.timing).await {
                return Some(Err(e));
            }
        }
        while let Some(event) = slave.poll_event() {
            tracing::debug!("{event:?}");
        }
        let upstreams = self.upstreams;
        while let Some(request) = slave.poll_request() {
            let (id, unit, pdu) = (request.id, request.unit, request.pdu.to_vec());
            if request.broadcast {
                // Executed as far as the line can tell (no reply); forwarded behind what came
                // before.
                let _ = slave.respond(id, &pdu);
                self.forwards.push_back((None, Box::pin(broadcast(upstreams, pdu))));
            } else {
                self.forwards.push_back((Some(id), Box::pin(forward(upstreams, unit, pdu, self.on_failure))));
            }
        }
        None
    }

    /// The oldest forward's answer. The line is read while it is under way: the engine keeps
    /// the request's slot and its timing, and stays silent on a master that does not wait.
    /// Cancel-safe: the forward is kept, pinned, until it has answered.
    async fn wait(&mut self) {
        let Some((_, forward)) = self.forwards.front_mut() else {
            return std::future::pending().await;
        };
        let reply = forward.as_mut().await;
        if let Some((Some(id), _)) = self.forwards.pop_front() {
            self.answered = Some((id, reply));
        }
    }

    fn on_end(&mut self, error: Option<io::Error>) -> io::Result<()> {
        error.map_or(Ok(()), Err)
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
        Err(e) => {
            if !matches!(e, Error::Exception { .. }) {
                tracing::info!(unit, "no answer from the TCP side: {e}");
            }
            answer_failure(function, &e, on_failure)
        }
    }
}

/// What the line gets for a failure on the TCP side: the forward gateway's own answer for it
/// ([`failure`]), so both directions answer one failure alike. What the device said, or a
/// request the client would not send, is always answered; silence, a bad reply or a server
/// that cannot be reached only with [`OnFailure::Exception`].
fn answer_failure(function: u8, error: &Error, on_failure: OnFailure) -> Option<Vec<u8>> {
    let (code, ended) = failure(error);
    (ended == Ended::Replied || on_failure == OnFailure::Exception).then(|| exception(function, code.value()))
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use ferrobus_proto::ExceptionCode;

    use super::*;

    #[test]
    fn a_failure_on_the_tcp_side_is_answered_as_the_forward_gateway_answers_it_when_asked() {
        let timeout = Error::Timeout { unit: 1, timeout: Duration::from_millis(5), attempts: 1, heard: None };
        let gone = Error::io("connecting", std::io::Error::from(std::io::ErrorKind::ConnectionRefused));
        let refused = Error::Exception {
            unit: 1,
            function: FunctionCode::from_u8(0x03),
            code: ExceptionCode::IllegalDataAddress,
        };
        for (error, code) in [(&timeout, 0x0B), (&gone, 0x0A), (&refused, 0x02)] {
            assert_eq!(answer_failure(0x03, error, OnFailure::Exception), Some(vec![0x83, code]), "{error}");
        }
        assert_eq!(answer_failure(0x03, &timeout, OnFailure::Silent), None);
        assert_eq!(answer_failure(0x03, &gone, OnFailure::Silent), None);
        assert_eq!(answer_failure(0x03, &refused, OnFailure::Silent), Some(vec![0x83, 0x02]), "the device's own word");
    }
}
