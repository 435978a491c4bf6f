//! The slave engine's request-out / response-in interface: a request the engine has framed
//! and admitted is handed out ([`Slave::poll_request`]), and finished whenever its answer is
//! ready ([`Slave::respond`], [`Slave::refuse`], [`Slave::ignore`], [`Slave::answer_with`]).
//! The engine keeps the request's slot and its timing meanwhile: the reply goes out no
//! earlier than t3.5 plus the response wait after the request, in request order.

use core::fmt;
use core::time::Duration;

use super::pending::{RequestId, State};
use super::{Admission, Core, Handler, Outcome, Slave, serve};
use crate::codes::ExceptionCode;
use crate::frame::Framing;
use crate::pdu::{CommEventCounter, MAX_PDU_LEN, Request, Response};
use crate::time::Instant;

/// How long a request handed out may wait for its answer unless
/// [`Slave::set_answer_limit`] says otherwise: after it, the request gets no reply.
pub const ANSWER_LIMIT: Duration = Duration::from_secs(10);

/// A request handed out by [`Slave::poll_request`].
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Incoming<'a> {
    /// What names it when it is answered.
    pub id: RequestId,
    /// The unit it was sent to (0 for a broadcast on a serial line).
    pub unit: u8,
    /// Its MBAP transaction id (0 on a serial line), for what logs the request.
    pub transaction: u16,
    /// Whether it was sent to all: it gets no reply, whatever it is answered with.
    pub broadcast: bool,
    /// Its PDU as it came (function code first), parsed or not.
    pub pdu: &'a [u8],
}

/// Why an answer was not taken.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[non_exhaustive]
pub enum AnswerError {
    /// The engine holds no request waiting under this id: never handed out, answered
    /// already, or given up at the answer limit.
    Unknown(RequestId),
    /// A reply PDU of this length: a PDU holds 1 to [`MAX_PDU_LEN`] bytes.
    BadLength(usize),
}

impl fmt::Display for AnswerError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            AnswerError::Unknown(id) => write!(f, "no request waits under id {}", id.0),
            AnswerError::BadLength(n) => write!(f, "a reply PDU of {n} bytes (1 to {MAX_PDU_LEN})"),
        }
    }
}

impl core::error::Error for AnswerError {}

/// The handler of a deferred `receive`: never called, since nothing is answered at once.
struct NoHandler;

impl Handler for NoHandler {}

impl<F: Framing> Slave<F> {
    /// Bytes arrived at `now`; returns how many were taken, as [`Slave::on_bytes`] does, but
    /// answers nothing: the requests framed wait in their slots for
    /// [`Slave::poll_request`].
    pub fn receive(&mut self, now: Instant, bytes: &[u8]) -> usize {
        self.feed::<NoHandler>(now, bytes, None)
    }

    /// `now` has come, as [`Slave::handle_timeout`], answering nothing: ends silent
    /// intervals and gives up on requests past their answer limit.
    pub fn wake(&mut self, now: Instant) {
        self.expire(now);
        self.framing.handle_timeout(now);
        self.receive(now, &[]);
    }

    /// The oldest request not yet handed out, now handed out: it waits for an answer under
    /// its id.
    pub fn poll_request(&mut self) -> Option<Incoming<'_>> {
        let entry = self.core.slots.first_mut(State::Queued)?;
        entry.state = State::HandedOut;
        Some(Incoming {
            id: entry.id,
            unit: entry.header.unit,
            transaction: entry.header.transaction,
            broadcast: entry.broadcast,
            pdu: entry.pdu(),
        })
    }

    /// Answers request `id` with `pdu` (a response PDU, an exception one too), due t3.5
    /// plus [`SlaveConfig::response_wait`](super::SlaveConfig::response_wait) after the
    /// request. A broadcast is finished as executed, without a reply.
    pub fn respond(&mut self, id: RequestId, pdu: &[u8]) -> Result<(), AnswerError> {
        if pdu.is_empty() || pdu.len() > MAX_PDU_LEN {
            return Err(AnswerError::BadLength(pdu.len()));
        }
        let wait = self.core.config.response_wait;
        let disposition = self.core.complete(id, Outcome::Reply(pdu), wait)?;
        if matches!(disposition, super::Disposition::Replied(_) | super::Disposition::Executed) {
            super::diag::bump(&mut self.core.comm_events);
        }
        self.apply();
        Ok(())
    }

    /// Answers request `id` with exception `code` (a broadcast: no reply).
    pub fn refuse(&mut self, id: RequestId, code: ExceptionCode) -> Result<(), AnswerError> {
        let wait = self.core.config.response_wait;
        self.core.complete(id, Outcome::Exception(code), wait)?;
        self.apply();
        Ok(())
    }

    /// Finishes request `id` without a reply, as if it had never come.
    pub fn ignore(&mut self, id: RequestId) -> Result<(), AnswerError> {
        self.core.complete(id, Outcome::Silent, self.core.config.response_wait)?;
        self.apply();
        Ok(())
    }

    /// Answers request `id` through `handler`, the one dispatch of every server: a request
    /// that does not parse gets the exception the spec names (a broadcast nothing), then
    /// [`Handler::admit`] decides, then exactly one data method serves it — or the engine
    /// itself, for 0x08 Diagnostics, 0x0B and 0x0C. A broadcast is executed on every unit
    /// the handler admits it for. The reply is due t3.5 plus the unit's
    /// [`Handler::response_wait`] after the request.
    pub fn answer_with<H: Handler + ?Sized>(&mut self, id: RequestId, handler: &mut H) -> Result<(), AnswerError> {
        let entry = self.core.slots.get_mut(id).filter(|e| e.is_waiting()).ok_or(AnswerError::Unknown(id))?;
        let (unit, broadcast, held, len) = (entry.header.unit, entry.broadcast, entry.pdu, entry.len);
        let wait = handler.response_wait(unit).unwrap_or(self.core.config.response_wait);
        let mut out = [0u8; MAX_PDU_LEN];
        let outcome = self.core.serve(handler, unit, broadcast, held.get(..len).unwrap_or_default(), &mut out);
        self.core.complete(id, outcome, wait)?;
        self.apply();
        Ok(())
    }
}

impl Core {
    /// What `handler` (or the engine, for its own functions) answers `pdu` with.
    fn serve<'o, H: Handler + ?Sized>(
        &mut self,
        handler: &mut H,
        unit: u8,
        broadcast: bool,
        pdu: &[u8],
        out: &'o mut [u8; MAX_PDU_LEN],
    ) -> Outcome<'o> {
        let request = match Request::parse(pdu) {
            Ok(request) => request,
            Err(_) if broadcast => return Outcome::Silent,
            Err(e) => return Outcome::Exception(e.exception_code()),
        };
        if broadcast {
            return self.broadcast(&request, handler);
        }
        match handler.admit(unit, false, &request) {
            Admission::Serve => {}
            Admission::Refuse(code) => return Outcome::Exception(code),
            Admission::Ignore => return Outcome::Silent,
        }
        let served = match request {
            Request::Diagnostics(d) => match self.diagnostics(&d, out) {
                Ok(Some(n)) => Ok(n),
                Ok(None) => return Outcome::Silent,
                Err(code) => Err(code),
            },
            Request::GetCommEventCounter(_) => {
                let reply = CommEventCounter { status: 0, event_count: self.comm_events };
                Response::GetCommEventCounter(reply).emit(out).map_err(|_| ExceptionCode::ServerDeviceFailure)
            }
            Request::GetCommEventLog(_) => self.event_log_reply(out),
            ref other => serve::serve(handler, unit, other, out),
        };
        match served {
            Ok(len) => {
                if !matches!(request, Request::GetCommEventCounter(_) | Request::GetCommEventLog(_)) {
                    super::diag::bump(&mut self.comm_events);
                }
                Outcome::Reply(out.get(..len).unwrap_or_default())
            }
            Err(code) => Outcome::Exception(code),
        }
    }
}
