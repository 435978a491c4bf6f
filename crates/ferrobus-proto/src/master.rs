//! The master (client) engine: one request in flight on a shared line. (Over Modbus/TCP,
//! [`pipeline`] keeps several in flight on one connection.)
//!
//! Spec: MODBUS over Serial Line V1.02 §2.4.1 (master state diagram) and §2.5.1.1 (t3.5).
//!
//! ```text
//!  submit ─▶ Queued ──(line silent for t3.5)──▶ poll_transmit ─┬─ unicast ─▶ AwaitingReply ─┬─ reply ───▶ Response / Exception
//!                                                              │                            └─ timeout ─▶ Failed(Timeout)
//!                                                              └─ no reply ──▶ Turnaround ──(delay)───▶ Sent
//! ```
//!
//! - **Gaps.** A request goes out only after the line has been silent for the framing's
//!   inter-frame gap (t3.5 on a serial line) since the last byte heard or sent — the rule
//!   drives such as the 3G3RX enforce by not answering. Bytes heard while waiting push the
//!   transmission back.
//! - **Matching.** While waiting, a frame from another unit, with another function code, from
//!   another transaction, or that is a request (our own echo, another master) is ignored and
//!   counted; only the reply can end the wait. A reply that does not answer the request (wrong
//!   byte count, a write echo that differs) fails it.
//! - **What was heard.** A timeout says what came instead of the reply, if anything
//!   ([`HeardInstead`]): a frame with a broken checksum, bytes that made no frame, a frame from
//!   another unit, under another transaction id, or with another function code. Silence,
//!   garbage, a bad CRC and the wrong unit are different diagnoses.
//! - **Outcomes.** An exception reply is a [`Completion::Exception`], a result like any other;
//!   [`Completion::Failed`] means no usable reply came.
//! - **Time.** The response timeout runs from the end of our transmission. A reply still
//!   arriving when it expires is given the time a whole frame takes to finish.
//! - **Owed replies.** RTU and ASCII have no transaction id, so a reply that comes after its
//!   request timed out looks like the reply to the next request of the same shape (over
//!   Modbus/TCP the ids tell it apart, and nothing is owed). The engine
//!   therefore remembers a request that timed out in silence (nothing from its unit was
//!   heard) as *owed* a reply — its unit, function code and, where the request implies it,
//!   the reply's length — and keeps the line closed after it: the next request (a retry, or
//!   anyone's next one to that unit) goes out only once the owed reply has been heard and
//!   dropped (counted in [`MasterStats::late_replies`]) and the line has been silent for the
//!   gap after it, or once [`MasterConfig::late_window`] has passed since the timeout without
//!   it. A request to another unit need not wait: the owed reply cannot pass for its reply
//!   (it names another unit), and if the two collide the result is a damaged frame, never a
//!   wrong value. But once such a request gets no usable reply but damage or other traffic —
//!   the units collide, or answer through one responder that is still busy with the late one
//!   (a multi-unit device, a simulator) — every request on the line waits for every owed
//!   reply from then on. Up to
//!   [`MAX_OWED`] units may be owed a reply at once; with as many owed, a
//!   request to yet another unit waits for the first to be settled. A unit whose owed reply
//!   never came is silent, not slow: its later timeouts owe nothing (and cost no late window)
//!   until a frame from it is heard again.
//! - **Suspect replies.** A reply later than the timeout plus the late window, to a request
//!   of the same unit, function and length, cannot be told from the next one's by its
//!   content; but the line knows when replies come. The engine learns each unit's usual reply
//!   delay (the 99th percentile of the delays from the end of the request to the start of the
//!   reply, once it has answered 20 times) and, to a unit whose owed reply never came, drops a
//!   reply that begins more than four times that delay plus 10 ms after the request: counted
//!   in [`MasterStats::suspect_replies`] and named in the timeout
//!   ([`HeardInstead::Suspect`]). A device that is really that slow now shows timeouts, never
//!   another request's values: size the timeout and the late window to it.
//! - **Too early.** On a wire no reply can begin before our request has finished leaving —
//!   the slave must have heard all of it, and the spec has it keep t3.5 of silence on top —
//!   so a reply that begins sooner than [`MasterConfig::min_reply_delay`] after the end of
//!   our transmission was on its way already (a stale reply to an earlier request, left in
//!   the port's or the adapter's buffer): it is dropped, counted in
//!   [`MasterStats::early_replies`] and named in the timeout ([`HeardInstead::TooEarly`]). The
//!   driver sets it for ports with a wire only: a pty delivers our request at once, and a
//!   peer on it may answer within microseconds (libmodbus does, 0.26 ms after a request that
//!   would take 4.6 ms on a 19200-baud wire).
//!

use core::fmt;
use core::time::Duration;

use crate::codes::{DiagnosticCode, ExceptionCode, FunctionCode, unit};
use crate::error::{BufferTooSmall, DiscardReason, PduError};
use crate::frame::{AduHeader, Direction, Framing, RxEvent, ascii, expire, feed, rtu};
use crate::pdu::{BitValues, MAX_PDU_LEN, MeiRequest, MeiResponse, Request, Response};
use crate::time::{Instant, earliest};

pub mod pipeline;
mod reply_times;

use reply_times::ReplyTimes;

/// Units that may be owed a late reply at once (see the module docs).
pub const MAX_OWED: usize = 4;

/// The largest frame the master transmits, in any framing (an ASCII frame of a 253-byte PDU).
pub const MAX_TX_LEN: usize = ascii::MAX_FRAME_CHARS;

/// Settings of the master engine.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct MasterConfig {
    /// How long to wait for a reply once the request has left. The spec's typical values are
    /// one to several seconds at 9600 baud; a drive's response wait (3G3RX C078, up to 1 s)
    /// comes on top of the reply's own transmission time.
    pub response_timeout: Duration,
    /// How long to keep the line quiet after a broadcast, which gets no reply, so that every
    /// slave can act on it (the spec's typical 100–200 ms).
    pub turnaround_delay: Duration,
    /// Drop our own transmission when it comes back: RS-485 adapters that do not disable
    /// their receiver while transmitting hear every byte they send.
    pub echo_suppression: bool,
    /// After a request timed out in silence, how long past its deadline its reply is still
    /// awaited (and the line kept closed) before the next request goes out; the wait ends
    /// as soon as the late reply has been heard and dropped. See the module docs.
    pub late_window: Duration,
    /// The soonest a reply may begin after our request has finished leaving, at the
    /// framing's character time: zero on a wire, where the slave must have heard the whole
    /// request first (t3.5 for slaves known to keep the spec's silence). A reply sooner is a
    /// stale one and is dropped. `None` where nothing bounds it (TCP, RTU over TCP, a pty).
    pub min_reply_delay: Option<Duration>,
}

impl Default for MasterConfig {
    fn default() -> Self {
        MasterConfig {
            response_timeout: Duration::from_secs(1),
            turnaround_delay: Duration::from_millis(100),
            echo_suppression: false,
            late_window: Duration::from_secs(1),
            min_reply_delay: None,
        }
    }
}

/// Why a request got no usable reply.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[non_exhaustive]
pub enum MasterError {
    /// No reply came within the response timeout.
    Timeout {
        /// The time waited after the request had left.
        waited: Duration,
        /// What came instead of the reply, if anything: `None` is silence.
        heard: Option<HeardInstead>,
    },
    /// A frame from the right unit with the right function code, but a malformed PDU.
    BadResponse(PduError),
    /// A well-formed reply that does not answer the request.
    Mismatch {
        /// The field that differs, e.g. `"byte count"`.
        field: &'static str,
        /// What the request called for.
        expected: u16,
        /// What the reply said.
        received: u16,
    },
    /// The buffer handed to [`Master::poll_transmit`] could not hold the request.
    TransmitBuffer(BufferTooSmall),
}

impl fmt::Display for MasterError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            MasterError::Timeout { waited, heard: None } => write!(f, "no reply within {} ms", waited.as_millis()),
            MasterError::Timeout { waited, heard: Some(heard) } => {
                write!(f, "no valid reply within {} ms: {heard}", waited.as_millis())
            }
            MasterError::BadResponse(e) => write!(f, "malformed reply: {e}"),
            MasterError::Mismatch { field, expected, received } => {
                write!(f, "reply does not answer the request: {field} {received}, expected {expected}")
            }
            MasterError::TransmitBuffer(e) => write!(f, "transmit {e}"),
        }
    }
}

impl core::error::Error for MasterError {}

/// What the master heard while it waited for a reply, instead of the reply (a frame, bytes,
/// an early reply: not the activity a scan's listener sums up): carried by
/// [`MasterError::Timeout`]. When several things came, the one that tells most about the unit
/// asked is kept (see [`HeardInstead::weight`]), the latest of equal weight.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum HeardInstead {
    /// A frame whose checksum (RTU CRC, ASCII LRC) was wrong: noise on the line, a missing
    /// termination, or a baud rate or parity that does not match.
    BadChecksum {
        /// The address and function code at its start, when it had them. The damage may be
        /// in these bytes too.
        head: Option<(u8, u8)>,
        /// The unit and the function code asked.
        expected: (u8, u8),
    },
    /// Bytes that did not make a frame (a frame cut short, noise, a bad header).
    Garbage {
        /// How many.
        bytes: usize,
        /// Why they made no frame.
        reason: DiscardReason,
    },
    /// A valid frame from another unit.
    OtherUnit {
        /// The unit that sent it.
        unit: u8,
        /// Its function code.
        function: u8,
    },
    /// A frame from the unit asked under another transaction id (Modbus/TCP): a late reply to
    /// an earlier request, or a gateway that does not echo the id.
    OtherTransaction {
        /// The transaction id it carried.
        transaction: u16,
        /// The transaction id of the request.
        expected: u16,
    },
    /// A frame from the unit asked with a function code that does not answer the request
    /// (a device that misreads the request, or a late reply to an earlier one).
    WrongFunction {
        /// The function code it carried.
        function: u8,
        /// The function code asked.
        expected: u8,
    },
    /// What would have been the reply began sooner after the request than any slave can
    /// answer ([`MasterConfig::min_reply_delay`]): a stale reply to an earlier request, left
    /// in the port's buffer or still on its way.
    TooEarly {
        /// From the start of our transmission to the start of the reply.
        after: Duration,
        /// From the start of our transmission to the soonest a reply can begin (the request's
        /// own transmission, and the minimum delay after it).
        earliest: Duration,
    },
    /// What would have been the reply, from a unit whose last owed reply never came, began
    /// far later than the unit usually answers: most likely that late reply, dropped (see
    /// the module docs).
    Suspect {
        /// From the end of our transmission to the start of the reply.
        after: Duration,
        /// The unit's usual delay (its 99th percentile).
        usual: Duration,
    },
}

impl HeardInstead {
    /// How much it says about the unit asked: a valid frame from it (3), a broken frame that
    /// names it (2), broken bytes (1), another unit's frame, which may be other traffic (0).
    pub fn weight(&self) -> u8 {
        match *self {
            HeardInstead::OtherTransaction { .. }
            | HeardInstead::WrongFunction { .. }
            | HeardInstead::TooEarly { .. }
            | HeardInstead::Suspect { .. } => 3,
            HeardInstead::BadChecksum { head: Some((from, _)), expected: (unit, _) } if from == unit => 2,
            HeardInstead::BadChecksum { .. } | HeardInstead::Garbage { .. } => 1,
            HeardInstead::OtherUnit { .. } => 0,
        }
    }

    /// Whether it is bytes damaged on the way (a bad checksum, or no frame at all): a line
    /// problem rather than a device one.
    pub fn is_damage(&self) -> bool {
        matches!(self, HeardInstead::BadChecksum { .. } | HeardInstead::Garbage { .. })
    }
}

impl fmt::Display for HeardInstead {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            HeardInstead::BadChecksum { head: Some((from, fc)), expected: (unit, function) } if from == unit => {
                write!(f, "unit {unit} answered, but the checksum was wrong ")?;
                if fc & !FunctionCode::EXCEPTION_BIT == function {
                    write!(f, "(function code 0x{fc:02X}, as asked)")
                } else {
                    write!(f, "(function code 0x{fc:02X}, expected 0x{function:02X})")
                }
            }
            HeardInstead::BadChecksum { head: Some((from, fc)), .. } => {
                write!(f, "a frame with a wrong checksum came (address {from}, function code 0x{fc:02X})")
            }
            HeardInstead::BadChecksum { head: None, .. } => f.write_str("a frame with a wrong checksum came"),
            HeardInstead::Garbage { bytes, reason } => {
                write!(f, "{bytes} byte{} came that made no frame ({reason})", if bytes == 1 { "" } else { "s" })
            }
            HeardInstead::OtherUnit { unit, function } => {
                write!(f, "unit {unit} sent a frame (function code 0x{function:02X}) instead, ignored")
            }
            HeardInstead::OtherTransaction { transaction, expected } => {
                write!(f, "a reply came under transaction id {transaction}, not {expected}, ignored")
            }
            HeardInstead::WrongFunction { function, expected } => write!(
                f,
                "the unit sent a frame with function code 0x{function:02X} instead of 0x{expected:02X}, ignored"
            ),
            HeardInstead::TooEarly { after, earliest } => write!(
                f,
                "a reply {} µs after the request, earlier than any slave can answer (not before {} µs): a stale reply, ignored",
                after.as_micros(),
                earliest.as_micros()
            ),
            HeardInstead::Suspect { after, usual } => write!(
                f,
                "a reply {} ms after the request, where the unit answers within {} ms, after an earlier reply of \
                 it never came: taken for that late reply, dropped",
                after.as_millis(),
                usual.as_millis().max(1)
            ),
        }
    }
}

/// Why [`Master::submit`] or [`Pipeline::submit`](pipeline::Pipeline::submit) refused a request.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[non_exhaustive]
pub enum SubmitError {
    /// A request is in flight, or its completion has not been polled yet ([`Master`]).
    Busy,
    /// The request does not fit the framing's buffer (cannot happen with the built-in codecs).
    Encode(BufferTooSmall),
    /// As many requests as the [`Pipeline`](pipeline::Pipeline) keeps in flight are
    /// outstanding: submitted, and their completions not polled yet.
    Full {
        /// The pipeline's limit ([`Pipeline::limit`](pipeline::Pipeline::limit)).
        limit: usize,
    },
}

impl fmt::Display for SubmitError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SubmitError::Busy => f.write_str("a request is already in flight"),
            SubmitError::Full { limit } => {
                write!(f, "{limit} requests are outstanding, the most this connection keeps in flight")
            }
            SubmitError::Encode(e) => write!(f, "cannot encode the request: {e}"),
        }
    }
}

impl core::error::Error for SubmitError {}

/// How a request ended.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Completion<'a> {
    /// The reply. For 0x01/0x02 it carries exactly the bits requested.
    Response(Response<'a>),
    /// The slave refused with this exception code.
    Exception(ExceptionCode),
    /// A request that gets no reply went out and the turnaround delay has passed: a
    /// broadcast, or 0x08/0x04 Force Listen Only.
    Sent,
    /// The reply to a request submitted with [`Master::submit_raw`], unparsed (function code
    /// first). Exceptions still come as [`Completion::Exception`].
    Raw(&'a [u8]),
    /// No usable reply.
    Failed(MasterError),
}

/// What the master has done since it was made. Counters wrap at 2³².
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug, Default)]
pub struct MasterStats {
    /// Requests transmitted.
    pub requests: u32,
    /// Normal replies accepted.
    pub responses: u32,
    /// Exception replies.
    pub exceptions: u32,
    /// Broadcasts transmitted.
    pub broadcasts: u32,
    /// Requests that timed out.
    pub timeouts: u32,
    /// Replies that were malformed or did not answer the request.
    pub bad_replies: u32,
    /// Frames heard that were not the awaited reply.
    pub ignored_frames: u32,
    /// Bytes of our own transmission dropped by echo suppression.
    pub echo_bytes: u32,
    /// Replies owed to requests that had timed out, heard late and dropped (see the module
    /// docs). Also counted in `ignored_frames`.
    pub late_replies: u32,
    /// Replies that began sooner after the request than any slave may answer, dropped
    /// ([`MasterConfig::min_reply_delay`]). Also counted in `ignored_frames`.
    pub early_replies: u32,
    /// Replies far later than their unit usually answers, after its last owed reply never
    /// came, dropped as that late reply ([`HeardInstead::Suspect`]). Also counted in
    /// `ignored_frames`.
    pub suspect_replies: u32,
}

#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum State {
    Idle,
    /// Waiting for the line to be silent; not before `not_before`.
    Queued {
        not_before: Instant,
    },
    /// Sent to a unit from `began` to `sent`; waiting for its reply until `deadline`.
    AwaitingReply {
        began: Instant,
        sent: Instant,
        deadline: Instant,
        /// Sent while another unit was owed a reply.
        beside_owed: bool,
    },
    /// Sent as broadcast; quiet until `until`.
    Turnaround {
        until: Instant,
    },
}

#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Outcome {
    /// The reply PDU is in `reply`; for bit reads, trim it to this many bits.
    Response {
        bits: Option<u16>,
    },
    /// The reply PDU to a raw request is in `reply`.
    Raw,
    Exception(ExceptionCode),
    Sent,
    Failed(MasterError),
}

impl Outcome {
    /// How the reply `pdu` — from the unit asked, under the request's transaction id, with
    /// the function code asked or its exception form — ends the request `request` (its
    /// PDU): for a raw request, the reply as it is or the exception it carries; otherwise
    /// the reply parsed and checked against the request ([`check_reply`]).
    fn of_reply(request: &[u8], raw: bool, pdu: &[u8]) -> Outcome {
        if raw {
            return match *pdu {
                [fc, code, ..] if fc & FunctionCode::EXCEPTION_BIT != 0 => {
                    Outcome::Exception(ExceptionCode::from_u8(code))
                }
                _ => Outcome::Raw,
            };
        }
        match (Request::parse(request), Response::parse(pdu)) {
            (_, Err(e)) | (Err(e), _) => Outcome::Failed(MasterError::BadResponse(e)),
            (_, Ok(Response::Exception(e))) => Outcome::Exception(e.code()),
            (Ok(request), Ok(response)) => match check_reply(&request, &response) {
                Ok(bits) => Outcome::Response { bits },
                Err(e) => Outcome::Failed(e),
            },
        }
    }

    /// Copies the reply `pdu` into `reply` if this outcome hands it out; returns its length
    /// then.
    fn keep_reply(self, reply: &mut [u8; MAX_PDU_LEN], pdu: &[u8]) -> Option<usize> {
        if !matches!(self, Outcome::Response { .. } | Outcome::Raw) {
            return None;
        }
        reply.get_mut(..pdu.len())?.copy_from_slice(pdu);
        Some(pdu.len())
    }

    /// The completion it makes, `reply` being the reply PDU kept for it.
    fn completion(self, reply: &[u8]) -> Completion<'_> {
        match self {
            Outcome::Exception(exception) => Completion::Exception(exception),
            Outcome::Sent => Completion::Sent,
            Outcome::Failed(e) => Completion::Failed(e),
            Outcome::Raw => Completion::Raw(reply),
            Outcome::Response { bits } => match Response::parse(reply) {
                Ok(response) => Completion::Response(trim_bits(response, bits)),
                Err(e) => Completion::Failed(MasterError::BadResponse(e)),
            },
        }
    }
}

impl MasterStats {
    /// Counts how a request ended.
    fn count(&mut self, outcome: Outcome) {
        let counter = match outcome {
            Outcome::Response { .. } | Outcome::Raw => &mut self.responses,
            Outcome::Exception(_) => &mut self.exceptions,
            Outcome::Sent => return,
            Outcome::Failed(MasterError::Timeout { .. }) => &mut self.timeouts,
            Outcome::Failed(_) => &mut self.bad_replies,
        };
        *counter = counter.wrapping_add(1);
    }
}

/// Keeps `heard` in `kept` unless what is kept tells more (see [`HeardInstead::weight`]).
fn keep_heard(kept: &mut Option<HeardInstead>, heard: HeardInstead) {
    if kept.is_none_or(|kept| heard.weight() >= kept.weight()) {
        *kept = Some(heard);
    }
}

/// When the wait for a reply due by `deadline` ends, as far as `framing` tells: at the
/// deadline, or, while a frame is still arriving past it, when that frame is complete but no
/// later than the time a whole frame takes after the deadline.
fn reply_wait_end<F: Framing>(framing: &F, deadline: Instant) -> Instant {
    match framing.poll_timeout() {
        Some(rx) if rx > deadline => rx.min(grace_end(framing, deadline)),
        _ => deadline,
    }
}

/// Whether at `now` the wait for a reply due by `deadline` is over ([`reply_wait_end`]).
fn reply_wait_is_over<F: Framing>(framing: &F, now: Instant, deadline: Instant) -> bool {
    if now < deadline {
        return false;
    }
    let in_progress = framing.poll_timeout().is_some_and(|rx| rx > now);
    !in_progress || now >= grace_end(framing, deadline)
}

/// The latest a reply still arriving at `deadline` may finish: a whole frame's time after it.
fn grace_end<F: Framing>(framing: &F, deadline: Instant) -> Instant {
    deadline.saturating_add(framing.transmit_time(rtu::MAX_ADU_LEN))
}

/// Whose owed replies a request waits for (see the module docs).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum OwedRule {
    /// Its own unit's only.
    SameUnit,
    /// Every unit's: a request sent beside another unit's owed reply got damage or other
    /// traffic instead of a reply.
    Every,
}

/// A reply still owed to a request that timed out (see the module docs).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
struct Owed {
    unit: u8,
    /// The function code asked.
    function: u8,
    /// The length of the reply PDU, where the request implies it.
    len: Option<usize>,
    /// When it stops being awaited.
    until: Instant,
}

impl Owed {
    /// Whether `frame`'s unit and PDU are the owed reply: its unit and function code, and its
    /// length if known, or the exception to it.
    fn is_answered_by(&self, unit: u8, pdu: &[u8]) -> bool {
        let Some(&function) = pdu.first() else { return false };
        if unit != self.unit || function & !FunctionCode::EXCEPTION_BIT != self.function {
            return false;
        }
        function & FunctionCode::EXCEPTION_BIT != 0 || self.len.is_none_or(|len| len == pdu.len())
    }

    /// Whether a damaged frame that began with `head` may be the owed reply.
    fn is_named_by(&self, head: Option<(u8, u8)>) -> bool {
        head.is_some_and(|(unit, function)| {
            unit == self.unit && function & !FunctionCode::EXCEPTION_BIT == self.function
        })
    }
}

/// The master engine over a framing `F` ([`RtuCodec`](crate::frame::rtu::RtuCodec),
/// [`AsciiCodec`](crate::frame::ascii::AsciiCodec) or [`MbapCodec`](crate::frame::mbap::MbapCodec)).
///
/// # Driving it
///
/// ```text
/// loop {
///     if let Some(n) = master.poll_transmit(now, &mut buf) { write(&buf[..n]) }
///     while let Some(c) = master.poll_event() { deliver(c) }
///     wait for bytes or until master.poll_timeout();
///     on bytes:   master.on_bytes(now, &bytes)
///     on timeout: master.handle_timeout(now)
/// }
/// ```
#[derive(Clone, Debug)]
pub struct Master<F> {
    framing: F,
    core: Core,
}

/// Everything but the framing, so that frames borrowed from the framing can be examined
/// while it is borrowed.
#[derive(Clone, Debug)]
struct Core {
    config: MasterConfig,
    /// Whether the framing is a serial one (broadcast exists, no transaction ids).
    serial: bool,
    state: State,
    unit: u8,
    transaction: u16,
    request: [u8; MAX_PDU_LEN],
    request_len: usize,
    /// Submitted with `submit_raw`: the reply is not checked against the request.
    raw: bool,
    /// No reply is expected (broadcast, 0x08/0x04).
    no_reply: bool,
    tx: [u8; MAX_TX_LEN],
    tx_len: usize,
    /// The part of our last transmission that may still come back as echo.
    echo_pos: usize,
    echo_len: usize,
    reply: [u8; MAX_PDU_LEN],
    reply_len: usize,
    outcome: Option<Outcome>,
    /// What came instead of the reply during this attempt.
    heard: Option<HeardInstead>,
    last_activity: Option<Instant>,
    /// When the frame now being received began: the chunk its first byte came in.
    rx_start: Instant,
    /// The replies owed to requests that timed out, while they are awaited: one per unit.
    owed: [Option<Owed>; MAX_OWED],
    /// A unit whose owed reply never came: silent, not slow, so its timeouts owe nothing
    /// until it is heard again.
    silent_unit: Option<u8>,
    /// How soon each unit answers.
    reply_times: ReplyTimes,
    /// Whose owed replies a request waits for.
    owed_rule: OwedRule,
    stats: MasterStats,
}

impl<F: Framing> Master<F> {
    /// A master over `framing`.
    pub fn new(framing: F, config: MasterConfig) -> Self {
        let serial = framing.supports_broadcast();
        Master {
            framing,
            core: Core {
                config,
                serial,
                state: State::Idle,
                unit: 0,
                transaction: 0,
                request: [0; MAX_PDU_LEN],
                request_len: 0,
                raw: false,
                no_reply: false,
                tx: [0; MAX_TX_LEN],
                tx_len: 0,
                echo_pos: 0,
                echo_len: 0,
                reply: [0; MAX_PDU_LEN],
                reply_len: 0,
                outcome: None,
                heard: None,
                last_activity: None,
                rx_start: Instant::ZERO,
                owed: [None; MAX_OWED],
                silent_unit: None,
                reply_times: ReplyTimes::new(),
                owed_rule: OwedRule::SameUnit,
                stats: MasterStats::default(),
            },
        }
    }

    /// The settings.
    pub fn config(&self) -> &MasterConfig {
        &self.core.config
    }

    /// Changes the settings; a request in flight keeps the deadline it has.
    pub fn set_config(&mut self, config: MasterConfig) {
        self.core.config = config;
    }

    /// The framing (for its statistics).
    pub fn framing(&self) -> &F {
        &self.framing
    }

    /// What the master has done.
    pub fn stats(&self) -> MasterStats {
        self.core.stats
    }

    /// Whether a new request can be submitted.
    pub fn is_idle(&self) -> bool {
        self.core.state == State::Idle && self.core.outcome.is_none()
    }

    /// Queues `request` for `unit`; it goes out once the line has been silent long enough.
    /// Unit 0 on a serial line is a broadcast, and 0x08/0x04 Force Listen Only is never
    /// answered: for those nothing is awaited but the turnaround delay.
    pub fn submit(&mut self, now: Instant, unit: u8, request: &Request<'_>) -> Result<(), SubmitError> {
        if !self.is_idle() {
            return Err(SubmitError::Busy);
        }
        let mut pdu = [0u8; MAX_PDU_LEN];
        let len = request.emit(&mut pdu).map_err(SubmitError::Encode)?;
        let listen_only =
            matches!(request, Request::Diagnostics(d) if d.sub_function() == DiagnosticCode::ForceListenOnly);
        self.queue(now, unit, pdu.get(..len).unwrap_or_default(), false, listen_only)
    }

    /// Queues any PDU for `unit`, valid or not: for probing devices and testing servers. The
    /// reply is matched by unit and function code only and handed back unparsed as
    /// [`Completion::Raw`].
    pub fn submit_raw(&mut self, now: Instant, unit: u8, pdu: &[u8]) -> Result<(), SubmitError> {
        if !self.is_idle() {
            return Err(SubmitError::Busy);
        }
        if pdu.is_empty() || pdu.len() > MAX_PDU_LEN {
            return Err(SubmitError::Encode(BufferTooSmall { needed: pdu.len().max(1), available: MAX_PDU_LEN }));
        }
        self.queue(now, unit, pdu, true, false)
    }

    fn queue(&mut self, now: Instant, unit: u8, pdu: &[u8], raw: bool, no_reply: bool) -> Result<(), SubmitError> {
        let core = &mut self.core;
        let transaction = core.transaction.wrapping_add(1);
        let header = AduHeader { unit, transaction };
        core.tx_len = self.framing.encode(header, pdu, &mut core.tx).map_err(SubmitError::Encode)?;
        if let Some(dst) = core.request.get_mut(..pdu.len()) {
            dst.copy_from_slice(pdu);
        }
        core.request_len = pdu.len();
        core.transaction = transaction;
        core.unit = unit;
        core.raw = raw;
        core.heard = None;
        core.no_reply = no_reply || unit::is_broadcast(unit, core.serial);
        core.state = State::Queued { not_before: now };
        Ok(())
    }

    /// Drops the request in flight, if any, and any completion not yet polled.
    pub fn abort(&mut self) {
        self.core.state = State::Idle;
        self.core.outcome = None;
    }

    /// When a queued request may go out: after its submission, after the gap, once no reply
    /// is owed by its unit, and, with [`MAX_OWED`] units owed one, once one of them is settled.
    fn transmit_at(&self, not_before: Instant) -> Instant {
        let gap = self.framing.inter_frame_gap();
        let quiet = self.core.last_activity.map_or(not_before, |t| t.saturating_add(gap));
        let owed = self.core.owed.iter().flatten();
        let unit = self.core.unit;
        let line = self.core.owed_rule == OwedRule::Every;
        let own = owed.clone().filter(|o| line || o.unit == unit).map(|o| o.until).max();
        let full = self.core.owed.iter().all(Option::is_some);
        let room = if full { owed.map(|o| o.until).min() } else { None };
        not_before.max(quiet).max(own.unwrap_or(not_before)).max(room.unwrap_or(not_before))
    }

    /// Whether a reply is owed to a request that timed out and still awaited at `now`.
    pub fn owes_reply(&self, now: Instant) -> bool {
        self.core.owed.iter().flatten().any(|owed| now < owed.until)
    }

    /// Until when the last reply owed to a request that timed out is awaited, if one is: the
    /// line must not be handed to another master before then (see the module docs).
    pub fn owed_until(&self) -> Option<Instant> {
        self.core.owed.iter().flatten().map(|owed| owed.until).max()
    }

    /// The bytes to write now, if a request is due: copies them into `buf` (which should hold
    /// [`MAX_TX_LEN`] bytes) and returns their length.
    pub fn poll_transmit(&mut self, now: Instant, buf: &mut [u8]) -> Option<usize> {
        let State::Queued { not_before } = self.core.state else {
            return None;
        };
        if now < self.transmit_at(not_before) {
            return None;
        }
        let core = &mut self.core;
        let n = core.tx_len;
        let (Some(dst), Some(src)) = (buf.get_mut(..n), core.tx.get(..n)) else {
            let e = BufferTooSmall { needed: n, available: buf.len() };
            core.finish(Outcome::Failed(MasterError::TransmitBuffer(e)));
            return None;
        };
        dst.copy_from_slice(src);
        // Anything heard before our request cannot be its reply, and an owed reply not heard
        // by now is no longer awaited.
        self.framing.reset();
        for slot in &mut core.owed {
            if let Some(owed) = slot.take_if(|owed| now >= owed.until) {
                // The late window passed in silence: the unit is dead, not slow.
                core.silent_unit = Some(owed.unit);
            }
        }
        let beside_owed = core.owed.iter().flatten().any(|o| o.unit != core.unit);
        let sent = now.saturating_add(self.framing.transmit_time(n));
        core.last_activity = Some(sent);
        core.echo_pos = 0;
        core.echo_len = if core.config.echo_suppression { n } else { 0 };
        if core.no_reply {
            let counter = if unit::is_broadcast(core.unit, core.serial) {
                &mut core.stats.broadcasts
            } else {
                &mut core.stats.requests
            };
            *counter = counter.wrapping_add(1);
            core.state = State::Turnaround { until: sent.saturating_add(core.config.turnaround_delay) };
        } else {
            core.stats.requests = core.stats.requests.wrapping_add(1);
            let deadline = sent.saturating_add(core.config.response_timeout);
            core.state = State::AwaitingReply { began: now, sent, deadline, beside_owed };
        }
        Some(n)
    }

    /// Bytes arrived at `now`.
    pub fn on_bytes(&mut self, now: Instant, bytes: &[u8]) {
        if bytes.is_empty() {
            return;
        }
        self.core.last_activity = Some(now);
        let bytes = self.core.strip_echo(bytes);
        if bytes.is_empty() {
            return;
        }
        if self.framing.poll_timeout().is_none() {
            // Nothing buffered: a frame in these bytes begins now.
            self.core.rx_start = now;
        }
        let Master { framing, core } = self;
        feed(framing, now, bytes, |event| {
            core.on_event(&event);
            // The next frame begins in this chunk at the earliest.
            core.rx_start = now;
        });
    }

    /// The next instant [`Master::handle_timeout`] must be called.
    pub fn poll_timeout(&self) -> Option<Instant> {
        let rx = self.framing.poll_timeout();
        let own = match self.core.state {
            State::Idle => None,
            State::Queued { not_before } => Some(self.transmit_at(not_before)),
            State::AwaitingReply { deadline, .. } => Some(reply_wait_end(&self.framing, deadline)),
            State::Turnaround { until } => Some(until),
        };
        earliest(own, rx)
    }

    /// `now` has come: ends silent intervals, turnarounds and timeouts that are due. Spurious
    /// calls do nothing.
    pub fn handle_timeout(&mut self, now: Instant) {
        let Master { framing, core } = self;
        expire(framing, now, |event| core.on_event(&event));
        match self.core.state {
            State::Turnaround { until } if now >= until => self.core.finish(Outcome::Sent),
            State::AwaitingReply { sent, deadline, .. } if reply_wait_is_over(&self.framing, now, deadline) => {
                let waited = now.saturating_duration_since(sent);
                let heard = self.core.heard;
                self.core.owe_reply(now);
                self.core.finish(Outcome::Failed(MasterError::Timeout { waited, heard }));
            }
            _ => {}
        }
    }

    /// How the last request ended, once. The reply borrows the master until the next call.
    pub fn poll_event(&mut self) -> Option<Completion<'_>> {
        let core = &mut self.core;
        let outcome = core.outcome.take()?;
        Some(outcome.completion(core.reply.get(..core.reply_len).unwrap_or_default()))
    }
}

impl Core {
    /// Removes the part of `bytes` that repeats our own transmission.
    fn strip_echo<'b>(&mut self, bytes: &'b [u8]) -> &'b [u8] {
        let pending = self.tx.get(self.echo_pos..self.echo_len).unwrap_or_default();
        let same = pending.iter().zip(bytes).take_while(|(a, b)| a == b).count();
        if same == 0 {
            // The echo is over, or something else is talking: stop looking for it.
            self.echo_len = 0;
            return bytes;
        }
        self.echo_pos = self.echo_pos.saturating_add(same);
        self.stats.echo_bytes = self.stats.echo_bytes.wrapping_add(u32::try_from(same).unwrap_or(u32::MAX));
        bytes.get(same..).unwrap_or_default()
    }

    /// Keeps `heard` unless something that tells more was heard already.
    fn hear(&mut self, heard: HeardInstead) {
        keep_heard(&mut self.heard, heard);
    }

    fn on_event(&mut self, event: &RxEvent<'_>) {
        let awaiting = matches!(self.state, State::AwaitingReply { .. });
        let asked = self.request.first().copied().unwrap_or_default();
        let heard_from = match *event {
            RxEvent::Frame(frame) => Some(frame.header.unit),
            RxEvent::Discarded { head, .. } => head.map(|(unit, _)| unit),
        };
        // A unit whose owed reply never came may be sending it now.
        let in_doubt = heard_from.is_some() && heard_from == self.silent_unit;
        if in_doubt {
            self.silent_unit = None;
        }
        let frame = match *event {
            RxEvent::Frame(frame) => frame,
            RxEvent::Discarded { bytes, reason, head, .. } => {
                if awaiting {
                    self.hear(match reason {
                        DiscardReason::ChecksumMismatch => {
                            HeardInstead::BadChecksum { head, expected: (self.unit, asked) }
                        }
                        reason => HeardInstead::Garbage { bytes, reason },
                    });
                } else if reason == DiscardReason::ChecksumMismatch {
                    // The owed reply, damaged: it came, so it is owed no more.
                    self.settle_owed(|o| o.is_named_by(head));
                }
                return;
            }
        };
        let settles = |o: &Owed| o.is_answered_by(frame.header.unit, frame.pdu);
        if !awaiting {
            // Awaited by nobody; the reply owed to a request that timed out settles it.
            self.settle_owed(settles);
            self.stats.ignored_frames = self.stats.ignored_frames.wrapping_add(1);
            return;
        }
        if frame.direction == Direction::Request {
            self.stats.ignored_frames = self.stats.ignored_frames.wrapping_add(1);
            return;
        }
        let function = frame.pdu.first().copied().unwrap_or_default();
        let answers = function & !FunctionCode::EXCEPTION_BIT == asked;
        let from_unit = frame.header.unit == self.unit;
        let in_transaction = self.serial || frame.header.transaction == self.transaction;
        if from_unit && in_transaction && answers && self.is_too_early() {
            self.stats.early_replies = self.stats.early_replies.wrapping_add(1);
            self.stats.ignored_frames = self.stats.ignored_frames.wrapping_add(1);
            return;
        }
        if from_unit && in_transaction && answers && in_doubt && self.is_suspect() {
            self.stats.suspect_replies = self.stats.suspect_replies.wrapping_add(1);
            self.stats.ignored_frames = self.stats.ignored_frames.wrapping_add(1);
            return;
        }
        if !from_unit {
            // Another unit's reply owed to an earlier request of ours, heard while we wait for
            // this one's: it came, so it is owed no more.
            self.settle_owed(settles);
        }
        if !from_unit || !in_transaction || !answers {
            // Not the reply (perhaps a late one to an earlier request), but worth naming if
            // the wait ends without one.
            self.hear(if !from_unit {
                HeardInstead::OtherUnit { unit: frame.header.unit, function }
            } else if !in_transaction {
                HeardInstead::OtherTransaction { transaction: frame.header.transaction, expected: self.transaction }
            } else {
                HeardInstead::WrongFunction { function, expected: asked }
            });
            self.stats.ignored_frames = self.stats.ignored_frames.wrapping_add(1);
            return;
        }
        // How soon the unit answers, learned from replies to a quiet line only: one that came
        // behind another frame (a late reply, a suspect one) was held up by it.
        if let Some(delay) = self.reply_delay().filter(|_| self.heard.is_none()) {
            self.reply_times.record(self.unit, delay);
        }
        let outcome = Outcome::of_reply(self.request.get(..self.request_len).unwrap_or_default(), self.raw, frame.pdu);
        if let Some(len) = outcome.keep_reply(&mut self.reply, frame.pdu) {
            self.reply_len = len;
        }
        self.finish(outcome);
    }

    /// Whether the frame just received began sooner after our request than any slave can
    /// answer; if so it is noted as heard.
    fn is_too_early(&mut self) -> bool {
        let (Some(delay), State::AwaitingReply { began, sent, .. }) = (self.config.min_reply_delay, self.state) else {
            return false;
        };
        let after = self.rx_start.saturating_duration_since(began);
        let earliest = sent.saturating_duration_since(began).saturating_add(delay);
        if after >= earliest {
            return false;
        }
        self.hear(HeardInstead::TooEarly { after, earliest });
        true
    }

    /// From the end of our transmission to the start of the frame just received, while a
    /// reply is awaited.
    fn reply_delay(&self) -> Option<Duration> {
        let State::AwaitingReply { sent, .. } = self.state else { return None };
        Some(self.rx_start.saturating_duration_since(sent))
    }

    /// Whether the reply just received, from a unit whose owed reply never came, began far
    /// later than the unit usually answers; if so it is noted as heard.
    fn is_suspect(&mut self) -> bool {
        let Some(after) = self.reply_delay() else { return false };
        let Some(usual) = self.reply_times.suspect(self.unit, after) else { return false };
        self.hear(HeardInstead::Suspect { after, usual });
        true
    }

    /// The request in flight timed out at `now`: unless its unit was heard answering (a
    /// damaged reply), its reply is owed until the late window has passed. Only where
    /// replies carry no transaction id (not Modbus/TCP, whose ids tell a late reply apart).
    fn owe_reply(&mut self, now: Instant) {
        let answered =
            matches!(self.heard, Some(HeardInstead::BadChecksum { head: Some((from, _)), .. }) if from == self.unit);
        if answered || !self.serial || self.silent_unit == Some(self.unit) {
            return;
        }
        let request = self.request.get(..self.request_len).unwrap_or_default();
        let len = if self.raw { None } else { Request::parse(request).ok().as_ref().and_then(reply_len) };
        let owed = Owed {
            unit: self.unit,
            function: request.first().copied().unwrap_or_default(),
            len,
            until: now.saturating_add(self.config.late_window),
        };
        // The unit's own slot if it still has one, else a free one: a request goes out only
        // with one free, so the earliest is replaced only should none be.
        let slots = &mut self.owed;
        let slot = match slots.iter().position(|o| o.is_some_and(|o| o.unit == owed.unit)) {
            Some(i) => i,
            None => slots.iter().position(Option::is_none).unwrap_or_else(|| {
                slots.iter().enumerate().min_by_key(|(_, o)| o.map(|o| o.until)).map_or(0, |(i, _)| i)
            }),
        };
        if let Some(slot) = slots.get_mut(slot) {
            *slot = Some(owed);
        }
    }

    /// The owed reply that `matches` picks has come and been dropped; the line opens after the
    /// gap that follows it.
    fn settle_owed(&mut self, matches: impl Fn(&Owed) -> bool) {
        if let Some(slot) = self.owed.iter_mut().find(|o| o.as_ref().is_some_and(&matches)) {
            *slot = None;
            self.stats.late_replies = self.stats.late_replies.wrapping_add(1);
        }
    }

    /// Counts the outcome and ends the request.
    fn finish(&mut self, outcome: Outcome) {
        let beside_owed = matches!(self.state, State::AwaitingReply { beside_owed: true, .. });
        if matches!(outcome, Outcome::Failed(_)) && beside_owed && self.heard.is_some() {
            // Sent beside another unit's owed reply, and what came instead of a usable reply
            // was damage or other traffic: that is no longer risked on this line.
            self.owed_rule = OwedRule::Every;
        }
        self.stats.count(outcome);
        self.outcome = Some(outcome);
        self.state = State::Idle;
    }
}

/// The length of the reply PDU `request` calls for, function code first, where it says.
fn reply_len(request: &Request<'_>) -> Option<usize> {
    let registers = |quantity: u16| usize::from(quantity).checked_mul(2)?.checked_add(2);
    match request {
        Request::ReadCoils(q) | Request::ReadDiscreteInputs(q) => q.response_byte_count().checked_add(2),
        Request::ReadHoldingRegisters(q) | Request::ReadInputRegisters(q) => registers(q.quantity()),
        Request::ReadWriteMultipleRegisters(q) => registers(q.read().quantity()),
        Request::WriteSingleCoil(_)
        | Request::WriteSingleRegister(_)
        | Request::WriteMultipleCoils(_)
        | Request::WriteMultipleRegisters(_) => Some(5),
        Request::MaskWriteRegister(_) => Some(7),
        _ => None,
    }
}

/// Trims a bit-read reply to the quantity requested.
fn trim_bits(response: Response<'_>, bits: Option<u16>) -> Response<'_> {
    fn trimmed(v: BitValues<'_>, bits: Option<u16>) -> BitValues<'_> {
        let bits = bits.and_then(|q| v.values().truncated(usize::from(q)));
        bits.and_then(|b| BitValues::new(b).ok()).unwrap_or(v)
    }
    match response {
        Response::ReadCoils(v) => Response::ReadCoils(trimmed(v, bits)),
        Response::ReadDiscreteInputs(v) => Response::ReadDiscreteInputs(trimmed(v, bits)),
        other => other,
    }
}

fn mismatch(field: &'static str, expected: usize, received: usize) -> MasterError {
    MasterError::Mismatch {
        field,
        expected: u16::try_from(expected).unwrap_or(u16::MAX),
        received: u16::try_from(received).unwrap_or(u16::MAX),
    }
}

/// Fails unless a field of the reply equals the request's.
fn field(field: &'static str, expected: u16, received: u16) -> Result<(), MasterError> {
    if expected == received { Ok(()) } else { Err(MasterError::Mismatch { field, expected, received }) }
}

/// Checks that `response` answers `request`; for bit reads, returns the quantity to trim to.
fn check_reply(request: &Request<'_>, response: &Response<'_>) -> Result<Option<u16>, MasterError> {
    match (request, response) {
        (Request::ReadCoils(q), Response::ReadCoils(r))
        | (Request::ReadDiscreteInputs(q), Response::ReadDiscreteInputs(r)) => {
            let got = r.values().byte_len();
            if got != q.response_byte_count() {
                return Err(mismatch("byte count", q.response_byte_count(), got));
            }
            return Ok(Some(q.quantity()));
        }
        (Request::ReadHoldingRegisters(q), Response::ReadHoldingRegisters(r))
        | (Request::ReadInputRegisters(q), Response::ReadInputRegisters(r)) => {
            if r.values().len() != usize::from(q.quantity()) {
                return Err(mismatch("register count", usize::from(q.quantity()), r.values().len()));
            }
        }
        (Request::ReadWriteMultipleRegisters(q), Response::ReadWriteMultipleRegisters(r)) => {
            let want = usize::from(q.read().quantity());
            if r.values().len() != want {
                return Err(mismatch("register count", want, r.values().len()));
            }
        }
        (Request::WriteSingleCoil(q), Response::WriteSingleCoil(r)) => {
            field("address", q.address, r.address)?;
            field("coil value", u16::from(q.value), u16::from(r.value))?;
        }
        (Request::WriteSingleRegister(q), Response::WriteSingleRegister(r)) => {
            field("address", q.address, r.address)?;
            field("value", q.value, r.value)?;
        }
        (Request::MaskWriteRegister(q), Response::MaskWriteRegister(r)) => {
            field("address", q.address, r.address)?;
            field("AND mask", q.and_mask, r.and_mask)?;
            field("OR mask", q.or_mask, r.or_mask)?;
        }
        (Request::WriteMultipleCoils(q), Response::WriteMultipleCoils(r)) => {
            field("start address", q.start(), r.start())?;
            field("quantity", q.quantity(), r.quantity())?;
        }
        (Request::WriteMultipleRegisters(q), Response::WriteMultipleRegisters(r)) => {
            field("start address", q.start(), r.start())?;
            field("quantity", q.quantity(), r.quantity())?;
        }
        (Request::WriteFileRecord(q), Response::WriteFileRecord(r)) => {
            if q != r {
                return Err(mismatch("file record echo (sub-requests)", q.len(), r.len()));
            }
        }
        (Request::Diagnostics(q), Response::Diagnostics(r)) => {
            field("sub-function", q.sub_function().value(), r.sub_function().value())?;
            if q.sub_function() == DiagnosticCode::ReturnQueryData && q.data() != r.data() {
                return Err(mismatch("echoed data (bytes)", q.data().len(), r.data().len()));
            }
        }
        (Request::ReadFileRecord(q), Response::ReadFileRecord(r)) => {
            if q.len() != r.len() {
                return Err(mismatch("sub-responses", q.len(), r.len()));
            }
            for (want, got) in q.iter().zip(r.iter()) {
                if usize::from(want.length) != got.len() {
                    return Err(mismatch("record length", usize::from(want.length), got.len()));
                }
            }
        }
        (Request::EncapsulatedInterface(q), Response::EncapsulatedInterface(r)) => match (q, r) {
            (MeiRequest::ReadDeviceId(q), MeiResponse::ReadDeviceId(r)) => {
                field("read device id code", u16::from(q.code().value()), u16::from(r.code().value()))?;
            }
            (MeiRequest::Other(q), MeiResponse::Other(r)) => {
                field("MEI type", u16::from(q.mei_type().value()), u16::from(r.mei_type().value()))?;
            }
            (MeiRequest::ReadDeviceId(_), MeiResponse::Other(r)) => {
                field("MEI type", 0x0E, u16::from(r.mei_type().value()))?;
            }
            (MeiRequest::Other(q), MeiResponse::ReadDeviceId(_)) => {
                field("MEI type", u16::from(q.mei_type().value()), 0x0E)?;
            }
        },
        (q, r) => field("function code", u16::from(q.function().value()), u16::from(r.function().value()))?,
    }
    Ok(None)
}

#[cfg(test)]
mod tests;
