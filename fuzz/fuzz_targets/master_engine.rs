//! The master engine (`Master<RtuCodec>`, 9600 8E1) with a request derived from the input —
//! parsed and sent with `submit`, or sent as it is with `submit_raw` — resubmitted whenever it
//! completes, and fed arbitrary reply bytes with gaps and timeouts.
//!
//! A second `RtuCodec` (the shadow) sees exactly what the master's own receiver sees — the
//! same chunks at the same instants, the same timeouts, a reset at every transmission — and
//! logs the frames. Asserted:
//!
//! - no panic, no spinning on a deadline that is already due, and every request ends;
//! - a `Completion::Response` (or `Raw`) only ever comes for a frame received after the
//!   request went out, from the unit asked, with the function code asked, and is that
//!   frame's PDU (for bit reads, trimmed to the quantity asked, padding zeroed; for register
//!   reads, with the register count asked); a `Completion::Exception` likewise comes from a
//!   frame of that unit carrying the function code's exception form;
//! - nothing completes before the request was transmitted; only a broadcast or 0x08/0x04
//!   completes as `Sent`, and neither gets a response or an exception;
//! - the request goes out as one RTU frame with a correct CRC and exactly the PDU submitted.
#![no_main]

use core::time::Duration;

use arbitrary::Arbitrary;
use ferrobus_proto::codes::DiagnosticCode;
use ferrobus_proto::crc::crc16;
use ferrobus_proto::frame::rtu::{RtuCodec, RtuFrame};
use ferrobus_proto::frame::{Direction, Expect, Framing, RxEvent, expire, feed};
use ferrobus_proto::master::{Completion, MAX_TX_LEN, Master, MasterConfig};
use ferrobus_proto::pdu::Request;
use ferrobus_proto::time::Instant;
use ferrobus_proto_fuzz::{MAX_TIMEOUTS_PER_WAIT, Step, assert_response_is, line_9600_8e1, request_from};
use libfuzzer_sys::fuzz_target;

#[derive(Arbitrary, Debug)]
struct Input {
    /// The unit asked; 0 is a broadcast.
    unit: u8,
    /// Response timeout in milliseconds (plus one).
    timeout_ms: u8,
    /// Turnaround delay after a request that gets no reply, in milliseconds.
    turnaround_ms: u8,
    strict_t1_5: bool,
    /// Send `request` as it is with `submit_raw`.
    raw: bool,
    /// The request PDU; with `submit`, if it does not parse, a read of 10 holding registers.
    request: Vec<u8>,
    /// How many times the request is sent in all (1–4).
    rounds: u8,
    steps: Vec<Step>,
}

/// A frame the shadow receiver delivered.
#[derive(Debug)]
struct Seen {
    unit: u8,
    pdu: Vec<u8>,
    direction: Direction,
}

/// What was submitted.
struct Submitted<'r> {
    unit: u8,
    /// The PDU as it goes on the wire.
    pdu: Vec<u8>,
    /// The request, unless submitted raw.
    request: Option<Request<'r>>,
}

impl Submitted<'_> {
    fn fc(&self) -> u8 {
        self.pdu[0]
    }

    /// Requests that get no reply: broadcasts and 0x08/0x04 Force Listen Only.
    fn no_reply(&self) -> bool {
        self.unit == 0
            || matches!(self.request, Some(Request::Diagnostics(d)) if d.sub_function() == DiagnosticCode::ForceListenOnly)
    }

    /// The frame the master must have taken as its reply: the first one after transmission
    /// that is not a request, from the unit asked, with the function code asked (or its
    /// exception form).
    fn reply_frame<'s>(&self, seen: &'s [Seen]) -> Option<&'s Seen> {
        seen.iter().find(|s| {
            s.direction != Direction::Request
                && s.unit == self.unit
                && s.pdu.first().map(|b| b & 0x7F) == Some(self.fc())
        })
    }

    fn check(&self, completion: &Completion<'_>, seen: &[Seen]) {
        let fc = self.fc();
        let reply = || {
            self.reply_frame(seen).unwrap_or_else(|| {
                panic!("{completion:?} without a frame from unit {} with fc {fc:#04x}: {seen:?}", self.unit)
            })
        };
        if !matches!(completion, Completion::Failed(_)) {
            assert_eq!(
                matches!(completion, Completion::Sent),
                self.no_reply(),
                "{completion:?} for {:?}",
                self.request
            );
        }
        match completion {
            Completion::Response(response) => {
                let request = self.request.as_ref().expect("a parsed response only for a parsed request");
                assert_response_is(request, response, &reply().pdu);
            }
            Completion::Raw(pdu) => {
                assert!(self.request.is_none(), "a raw reply to a parsed request");
                assert_eq!(*pdu, reply().pdu.as_slice(), "the raw reply is not the frame received");
            }
            Completion::Exception(code) => {
                let frame = reply();
                assert_eq!(frame.pdu[0], fc | 0x80, "exception from a normal reply");
                assert_eq!(frame.pdu.get(1).copied(), Some(code.value()));
            }
            Completion::Sent | Completion::Failed(_) => {}
        }
    }
}

struct Harness<'r> {
    master: Master<RtuCodec>,
    shadow: RtuCodec,
    submitted: Submitted<'r>,
    raw_input: &'r [u8],
    t: Instant,
    /// Frames the shadow saw since the request in flight went out; `None` before that.
    since_tx: Option<Vec<Seen>>,
    submits_left: u8,
    completions: u32,
}

impl Harness<'_> {
    fn record(log: &mut Option<Vec<Seen>>, event: &RxEvent<'_>) {
        if let (Some(log), RxEvent::Frame(adu)) = (log.as_mut(), event) {
            log.push(Seen { unit: adu.header.unit, pdu: adu.pdu.to_vec(), direction: adu.direction });
        }
    }

    fn on_bytes(&mut self, bytes: &[u8]) {
        let now = self.t;
        self.master.on_bytes(now, bytes);
        if !bytes.is_empty() {
            let log = &mut self.since_tx;
            feed(&mut self.shadow, now, bytes, |ev| Self::record(log, &ev));
        }
    }

    fn handle_timeout(&mut self) {
        let now = self.t;
        self.master.handle_timeout(now);
        let log = &mut self.since_tx;
        expire(&mut self.shadow, now, |ev| Self::record(log, &ev));
    }

    fn submit(&mut self) {
        let result = match self.submitted.request {
            Some(request) => self.master.submit(self.t, self.submitted.unit, &request),
            None => self.master.submit_raw(self.t, self.submitted.unit, self.raw_input),
        };
        result.expect("an idle master takes the request");
        assert!(!self.master.is_idle());
    }

    /// Transmits, collects the completion and resubmits, at `self.t`.
    fn poll(&mut self) {
        let mut buf = [0xA5u8; MAX_TX_LEN];
        if let Some(n) = self.master.poll_transmit(self.t, &mut buf) {
            let frame = &buf[..n];
            assert_eq!(crc16(frame), 0, "bad CRC on transmitted {frame:02X?}");
            let rtu = RtuFrame::new_checked(frame).expect("the request is a valid RTU frame");
            assert_eq!(rtu.unit(), self.submitted.unit);
            assert_eq!(rtu.pdu(), self.submitted.pdu.as_slice(), "transmitted another PDU than submitted");
            assert!(self.since_tx.is_none(), "transmitted twice for one submission");
            self.shadow.reset();
            self.since_tx = Some(Vec::new());
        }
        if let Some(completion) = self.master.poll_event() {
            self.completions += 1;
            let seen = self.since_tx.take().unwrap_or_else(|| panic!("{completion:?} before the request went out"));
            self.submitted.check(&completion, &seen);
        }
        if self.master.is_idle() && self.submits_left > 0 {
            self.submits_left -= 1;
            self.submit();
        }
    }

    fn run_until(&mut self, until: Option<Instant>) {
        for round in 0.. {
            self.poll();
            let Some(deadline) = self.master.poll_timeout() else { return };
            if until.is_some_and(|u| deadline > u) {
                return;
            }
            assert!(round < MAX_TIMEOUTS_PER_WAIT, "master keeps asking for timeouts ({deadline}, now {})", self.t);
            self.t = self.t.max(deadline);
            self.handle_timeout();
        }
    }
}

fuzz_target!(|input: Input| {
    let (request, pdu) = request_from(input.raw, &input.request);
    let timing = line_9600_8e1();
    let codec = RtuCodec::new(timing, Expect::Responses).with_strict_t1_5(input.strict_t1_5);
    let config = MasterConfig {
        response_timeout: Duration::from_millis(1 + u64::from(input.timeout_ms)),
        turnaround_delay: Duration::from_millis(u64::from(input.turnaround_ms)),
        echo_suppression: false,
        ..MasterConfig::default()
    };
    let mut h = Harness {
        master: Master::new(codec.clone(), config),
        shadow: codec,
        submitted: Submitted { unit: input.unit, pdu, request },
        raw_input: &input.request,
        t: Instant::ZERO,
        since_tx: None,
        submits_left: input.rounds.clamp(1, 4),
        completions: 0,
    };
    for step in &input.steps {
        let arrival = step.arrival(h.t);
        h.run_until(Some(arrival));
        h.t = arrival;
        h.on_bytes(&step.bytes);
        h.poll();
    }
    h.run_until(None);
    assert!(h.master.is_idle(), "master still busy after all its deadlines");
    let stats = h.master.stats();
    assert_eq!(stats.requests + stats.broadcasts, h.completions, "{stats:?}");
});
