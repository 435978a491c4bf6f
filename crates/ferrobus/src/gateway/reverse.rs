//! The reverse gateway: a slave on the serial line for the units listed, forwarding each
//! request to the Modbus/TCP server that unit stands for, so that a serial PLC master reaches
//! TCP devices.
//!
//! The serial side is the slave's receiver (the RTU codec, frames found by length first and
//! by t3.5 second); the master waits for one reply at a time, so requests are forwarded one
//! at a time, in the order they came. A reply goes out no earlier than t3.5 after the
//! request's last character, through the one RS-485-aware writer. A request for a unit not
//! listed, a frame that can only be another slave's reply, and a broadcast get no reply (a
//! broadcast write is forwarded to every server). When the TCP side gives no answer —
//! a timeout, a refused connection — the line gets silence or, with
//! [`OnFailure::Exception`], 0x0B (0x0A when the server cannot be reached at all).

use std::collections::BTreeMap;
use std::io;

use ferrobus_proto::frame::{AduHeader, Direction, Framing, RxEvent, feed};
use ferrobus_proto::pdu::Request;
use ferrobus_proto::{ExceptionCode, FunctionCode};
use tokio::io::AsyncReadExt;

use super::line::exception;
use crate::clock::Clock;
use crate::port::{BoxPort, Transport};
use crate::pump::{Codec, Hex, Role, write_frame};
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
    let mut codec = Codec::for_transport(transport, Role::Server);
    let clock = Clock::new();
    let (rs485, timing) = (transport.rs485(), *transport.timing());
    let mut rx = vec![0u8; 1024];
    let mut tx = [0u8; 300];
    loop {
        let deadline = codec.poll_timeout().map(|t| clock.to_tokio(t));
        let sleep = async {
            match deadline {
                Some(at) => tokio::time::sleep_until(at).await,
                None => std::future::pending().await,
            }
        };
        let mut requests = Vec::new();
        tokio::select! {
            read = port.read(&mut rx) => {
                let n = read?;
                if n == 0 {
                    return Ok(());
                }
                let at = port.last_arrival().map_or_else(|| clock.now(), |t| clock.from_tokio(t));
                let bytes = rx.get(..n).unwrap_or_default();
                feed(&mut codec, at, bytes, |event| take(&event, &mut requests));
            }
            () = sleep => {
                codec.handle_timeout(clock.now());
                while let Some(event) = codec.poll_event() {
                    take(&event, &mut requests);
                }
            }
        }
        for (unit, pdu, end) in requests {
            let Some(reply) = forward(upstreams, unit, &pdu, on_failure).await else { continue };
            let Ok(n) = codec.encode(AduHeader::unit(unit), &reply, &mut tx) else { continue };
            // Never before t3.5 after the request's last character.
            tokio::time::sleep_until(
                clock.to_tokio(end).checked_add(codec.inter_frame_gap()).unwrap_or_else(tokio::time::Instant::now),
            )
            .await;
            tracing::info!(unit, "reply {}", Hex(&reply));
            write_frame(&mut port, tx.get(..n).unwrap_or_default(), rs485, &timing).await?;
        }
    }
}

/// Keeps a request frame: (unit, PDU, when its last byte came).
fn take(event: &RxEvent<'_>, requests: &mut Vec<(u8, Vec<u8>, ferrobus_proto::Instant)>) {
    if let RxEvent::Frame(frame) = *event {
        if frame.direction != Direction::Response {
            requests.push((frame.header.unit, frame.pdu.to_vec(), frame.end));
        }
    }
}

/// The reply for the line, if any.
async fn forward(upstreams: &BTreeMap<u8, Upstream>, unit: u8, pdu: &[u8], on_failure: OnFailure) -> Option<Vec<u8>> {
    let function = pdu.first().copied().unwrap_or_default();
    if unit == 0 {
        if FunctionCode::from_u8(function).is_write() {
            for upstream in upstreams.values() {
                if let Err(e) = upstream.client.raw(upstream.unit, pdu).await {
                    tracing::info!("broadcast to unit {}: {e}", upstream.unit);
                }
            }
        }
        return None;
    }
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
