//! The pipelined Modbus/TCP master (`master::pipeline::Pipeline`, 1–16 in flight) with
//! requests derived from the input — parsed and sent with `submit`, or sent as they are with
//! `submit_raw` — submitted, answered, timed out and aborted in any interleaving: replies built
//! for a request picked from those submitted (plausible ones, exceptions, any PDU, from its unit
//! or another, under its id or another), arbitrary bytes, and chunks cut anywhere.
//!
//! A second `MbapCodec` (the shadow) sees exactly what the pipeline's own receiver sees — the
//! same chunks at the same instants, a reset at every abort — and logs the frames. Asserted:
//!
//! - no panic, no spinning on a deadline that is already due (after `handle_timeout(now)`,
//!   `poll_timeout()` is later than `now`), and every request ends (or is aborted) once;
//! - never more requests outstanding than the limit, and `submit` refused with `Full` exactly
//!   when there is no room;
//! - the requests go out in the order they were submitted, each as one MBAP frame under its
//!   ticket's transaction id, to its unit, with exactly the PDU submitted;
//! - a `Completion::Response` (or `Raw`) only ever comes for a frame received after the
//!   request went out, under its ticket's transaction id, from its unit, with the function
//!   code asked, and is that frame's PDU (for bit reads, trimmed to the quantity asked,
//!   padding zeroed; for register reads, with the register count asked); a
//!   `Completion::Exception` likewise comes from such a frame carrying the exception form;
//! - nothing completes before it was transmitted; only 0x08/0x04 completes as `Sent`, and it
//!   always does;
//! - `stats().requests` counts the frames transmitted.
#![no_main]

use core::time::Duration;
use std::collections::HashMap;

use arbitrary::Arbitrary;
use ferrobus_proto::codes::DiagnosticCode;
use ferrobus_proto::frame::mbap::{MAX_ADU_LEN, MbapCodec, encode_pdu};
use ferrobus_proto::frame::{AduHeader, Framing, RxEvent, feed};
use ferrobus_proto::master::pipeline::{Pipeline, Ticket};
use ferrobus_proto::master::{Completion, SubmitError};
use ferrobus_proto::pdu::{MAX_PDU_LEN, Request};
use ferrobus_proto::time::Instant;
use ferrobus_proto_fuzz::{MAX_TIMEOUTS_PER_WAIT, assert_response_is, request_from};
use libfuzzer_sys::fuzz_target;

#[derive(Arbitrary, Debug)]
struct Input {
    /// The most requests in flight (clamped by the pipeline to 1–16).
    in_flight: u8,
    /// The requests to submit, taken in turn.
    templates: Vec<Template>,
    ops: Vec<Op>,
}

#[derive(Arbitrary, Debug)]
struct Template {
    unit: u8,
    /// Response timeout in milliseconds (plus one).
    timeout_ms: u8,
    /// Send `request` as it is with `submit_raw`.
    raw: bool,
    /// The request PDU; with `submit`, if it does not parse, a read of 10 holding registers.
    request: Vec<u8>,
}

#[derive(Arbitrary, Debug)]
enum Op {
    /// Submits the next template.
    Submit,
    /// Queues a frame for the request submitted `pick`-th from the last (or under `id` to
    /// unit 1 if there is none, or `id` is set).
    Reply { pick: u8, id: Option<u16>, other_unit: bool, body: Body, data: Vec<u8> },
    /// Queues bytes as they are.
    Bytes(Vec<u8>),
    /// After `gap_us` µs, delivers the first `len` bytes queued.
    Deliver { gap_us: u16, len: u16 },
    /// Lets `ms` milliseconds pass.
    Wait { ms: u8 },
    /// Takes the completions.
    Poll,
    /// The connection is lost.
    Abort,
}

#[derive(Arbitrary, Debug)]
enum Body {
    /// What the request calls for, filled from `data`.
    Plausible,
    /// The exception form of the function code, with the first byte of `data` as the code.
    Exception,
    /// `data` as the PDU.
    Any,
}

/// A request submitted.
#[derive(Debug)]
struct Submitted<'r> {
    ticket: Ticket,
    unit: u8,
    /// The PDU as it goes on the wire.
    pdu: Vec<u8>,
    /// The request, unless submitted raw.
    request: Option<Request<'r>>,
    /// How many frames the shadow had logged when it went out; `None` before that.
    transmitted: Option<usize>,
    ended: bool,
    aborted: bool,
}

impl Submitted<'_> {
    fn fc(&self) -> u8 {
        self.pdu[0]
    }

    fn listen_only(&self) -> bool {
        matches!(self.request, Some(Request::Diagnostics(d)) if d.sub_function() == DiagnosticCode::ForceListenOnly)
    }

    /// A quantity field of the request (bytes 3 and 4), for building a plausible reply.
    fn quantity(&self) -> usize {
        usize::from(u16::from_be_bytes([self.pdu.get(3).copied().unwrap_or(0), self.pdu.get(4).copied().unwrap_or(0)]))
    }

    /// What the request calls for, its data filled from `data`.
    fn plausible(&self, data: &[u8]) -> Vec<u8> {
        let fc = self.fc();
        let fill = |n: usize| (0..n).map(|i| data.get(i % data.len().max(1)).copied().unwrap_or(0x5A));
        let counted = |n: usize| {
            let n = n.min(250);
            let mut pdu = vec![fc, n as u8];
            pdu.extend(fill(n));
            pdu
        };
        match fc {
            0x01 | 0x02 => counted(self.quantity().div_ceil(8)),
            0x03 | 0x04 | 0x17 => counted(self.quantity() * 2),
            0x05 | 0x06 | 0x0F | 0x10 => self.pdu[..self.pdu.len().min(5)].to_vec(),
            0x16 => self.pdu[..self.pdu.len().min(7)].to_vec(),
            0x08 => self.pdu.clone(),
            _ => {
                let mut pdu = vec![fc];
                pdu.extend(fill(data.len().min(MAX_PDU_LEN - 1)));
                pdu
            }
        }
    }

    fn check(&self, completion: &Completion<'_>, log: &[(u16, u8, Vec<u8>)]) {
        let fc = self.fc();
        let Some(from) = self.transmitted else { panic!("{completion:?} before {:?} went out", self.ticket) };
        let reply = || {
            log[from..]
                .iter()
                .find(|(id, unit, pdu)| *id == self.ticket.transaction() && *unit == self.unit && pdu[0] & 0x7F == fc)
                .map(|(_, _, pdu)| pdu.as_slice())
                .unwrap_or_else(|| {
                    panic!("{completion:?} without a frame under {:?} from unit {}", self.ticket, self.unit)
                })
        };
        assert_eq!(matches!(completion, Completion::Sent), self.listen_only(), "{completion:?} for {:?}", self.request);
        match completion {
            Completion::Response(response) => {
                let request = self.request.as_ref().expect("a parsed response only for a parsed request");
                assert_response_is(request, response, reply());
            }
            Completion::Raw(pdu) => {
                assert!(self.request.is_none(), "a raw reply to a parsed request");
                assert_eq!(*pdu, reply(), "the raw reply is not the frame received");
            }
            Completion::Exception(code) => {
                let frame = reply();
                assert_eq!(frame[0], fc | 0x80, "exception from a normal reply");
                assert_eq!(frame.get(1).copied(), Some(code.value()));
            }
            Completion::Sent | Completion::Failed(_) => {}
        }
    }
}

struct Harness<'r> {
    pipeline: Pipeline,
    shadow: MbapCodec,
    /// Every frame the shadow found: transaction id, unit, PDU.
    log: Vec<(u16, u8, Vec<u8>)>,
    submitted: Vec<Submitted<'r>>,
    /// Indexes in `submitted` of the tickets outstanding.
    live: HashMap<Ticket, usize>,
    /// Indexes in `submitted` not transmitted yet, in submission order.
    queue: Vec<usize>,
    /// Bytes not delivered yet.
    pending: Vec<u8>,
    t: Instant,
    transmitted: u32,
}

impl<'r> Harness<'r> {
    fn submit(&mut self, template: &'r Template) {
        let (request, pdu) = request_from(template.raw, &template.request);
        let timeout = Duration::from_millis(1 + u64::from(template.timeout_ms));
        let had_room = self.pipeline.has_room();
        let result = match request {
            Some(request) => self.pipeline.submit(self.t, template.unit, &request, timeout),
            None => self.pipeline.submit_raw(self.t, template.unit, &pdu, timeout),
        };
        match result {
            Ok(ticket) => {
                assert!(had_room, "took a request without room");
                assert!(ticket.slot() < self.pipeline.limit(), "{ticket:?} beyond the limit");
                let index = self.submitted.len();
                assert!(self.live.insert(ticket, index).is_none(), "{ticket:?} given twice");
                self.queue.push(index);
                self.submitted.push(Submitted {
                    ticket,
                    unit: template.unit,
                    pdu,
                    request,
                    transmitted: None,
                    ended: false,
                    aborted: false,
                });
            }
            Err(e) => {
                assert!(!had_room, "refused with room: {e:?}");
                assert_eq!(e, SubmitError::Full { limit: self.pipeline.limit() });
            }
        }
        assert!(self.pipeline.outstanding() <= self.pipeline.limit());
    }

    fn reply(&mut self, pick: u8, id: Option<u16>, other_unit: bool, body: &Body, data: &[u8]) {
        let target = match id {
            None if !self.submitted.is_empty() => {
                let back = usize::from(pick) % self.submitted.len();
                Some(&self.submitted[self.submitted.len() - 1 - back])
            }
            _ => None,
        };
        let (transaction, unit) = target.map_or((id.unwrap_or(0), 1), |s| (s.ticket.transaction(), s.unit));
        let fc = target.map_or(0x03, Submitted::fc);
        let pdu = match body {
            Body::Plausible => target.map_or_else(|| vec![0x03, 0x02, 0x00, 0x00], |s| s.plausible(data)),
            Body::Exception => vec![fc | 0x80, data.first().copied().unwrap_or(0x02)],
            Body::Any if data.is_empty() => vec![fc],
            Body::Any => data[..data.len().min(MAX_PDU_LEN)].to_vec(),
        };
        let unit = if other_unit { unit.wrapping_add(1) } else { unit };
        let mut frame = [0u8; MAX_ADU_LEN];
        let n = encode_pdu(AduHeader { unit, transaction }, &pdu, &mut frame).expect("a PDU fits");
        self.pending.extend_from_slice(&frame[..n]);
    }

    fn deliver(&mut self, len: usize) {
        let n = len.min(self.pending.len());
        let bytes: Vec<u8> = self.pending.drain(..n).collect();
        self.pipeline.on_bytes(self.t, &bytes);
        let log = &mut self.log;
        feed(&mut self.shadow, self.t, &bytes, |event| {
            if let RxEvent::Frame(frame) = event {
                log.push((frame.header.transaction, frame.header.unit, frame.pdu.to_vec()));
            }
        });
    }

    /// Takes every frame due, as a driver does before one write.
    fn transmit(&mut self) {
        let mut buf = [0xA5u8; MAX_ADU_LEN];
        while let Some(n) = self.pipeline.poll_transmit(self.t, &mut buf) {
            assert!(!self.queue.is_empty(), "transmitted with nothing queued");
            let sent = &mut self.submitted[self.queue.remove(0)];
            let mut want = [0u8; MAX_ADU_LEN];
            let header = AduHeader { unit: sent.unit, transaction: sent.ticket.transaction() };
            let len = encode_pdu(header, &sent.pdu, &mut want).expect("fits");
            assert_eq!(&buf[..n], &want[..len], "not the next request submitted, or not its PDU");
            assert!(sent.transmitted.is_none(), "transmitted twice");
            sent.transmitted = Some(self.log.len());
            self.transmitted += 1;
            buf = [0xA5; MAX_ADU_LEN];
        }
    }

    fn poll(&mut self) {
        while let Some((ticket, completion)) = self.pipeline.poll_event() {
            let index = self.live.remove(&ticket).unwrap_or_else(|| panic!("{ticket:?} completed twice or unknown"));
            let sent = &mut self.submitted[index];
            assert!(!sent.ended && !sent.aborted);
            sent.ended = true;
            sent.check(&completion, &self.log);
        }
    }

    /// Handles every timeout due by `until`, transmitting as a driver does.
    fn run_until(&mut self, until: Option<Instant>) {
        for round in 0.. {
            self.transmit();
            let Some(deadline) = self.pipeline.poll_timeout() else { return };
            assert!(deadline > self.t || round == 0, "deadline {deadline} still due after handling it at {}", self.t);
            if until.is_some_and(|u| deadline > u) {
                return;
            }
            assert!(round < MAX_TIMEOUTS_PER_WAIT, "pipeline keeps asking for timeouts ({deadline}, now {})", self.t);
            self.t = self.t.max(deadline);
            self.pipeline.handle_timeout(self.t);
        }
    }

    fn abort(&mut self) {
        self.pipeline.abort();
        self.shadow.reset();
        for (_, index) in self.live.drain() {
            self.submitted[index].aborted = true;
        }
        self.queue.clear();
        assert_eq!(self.pipeline.outstanding(), 0);
        assert_eq!(self.pipeline.poll_timeout(), None);
    }
}

fuzz_target!(|input: Input| {
    let mut h = Harness {
        pipeline: Pipeline::new(MbapCodec::new(), usize::from(input.in_flight)),
        shadow: MbapCodec::new(),
        log: Vec::new(),
        submitted: Vec::new(),
        live: HashMap::new(),
        queue: Vec::new(),
        pending: Vec::new(),
        t: Instant::ZERO,
        transmitted: 0,
    };
    let mut templates = input.templates.iter().cycle();
    for op in &input.ops {
        match op {
            Op::Submit => {
                if let Some(template) = templates.next() {
                    h.submit(template);
                }
            }
            Op::Reply { pick, id, other_unit, body, data } => h.reply(*pick, *id, *other_unit, body, data),
            Op::Bytes(bytes) => h.pending.extend_from_slice(bytes),
            Op::Deliver { gap_us, len } => {
                let at = h.t.saturating_add(Duration::from_micros(u64::from(*gap_us)));
                h.run_until(Some(at));
                h.t = at;
                h.deliver(usize::from(*len));
            }
            Op::Wait { ms } => {
                let at = h.t.saturating_add(Duration::from_millis(u64::from(*ms)));
                h.run_until(Some(at));
                h.t = at;
            }
            Op::Poll => h.poll(),
            Op::Abort => h.abort(),
        }
        h.transmit();
        assert_eq!(h.pipeline.outstanding(), h.live.len());
    }
    let rest = h.pending.len();
    h.deliver(rest);
    h.run_until(None);
    h.poll();
    assert_eq!(h.pipeline.outstanding(), 0, "requests outstanding after all their deadlines");
    for sent in &h.submitted {
        assert!(sent.ended != sent.aborted, "{sent:?} neither ended nor aborted");
    }
    assert_eq!(h.pipeline.stats().requests, h.transmitted, "{:?}", h.pipeline.stats());
});
